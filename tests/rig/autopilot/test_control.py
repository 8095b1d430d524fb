"""The control cascade against closed-form cases: allocation inverse, rate loop on a known
inertia, attitude error law, position → thrust mapping."""

import math

import numpy as np
import pytest
from scipy import signal

from quad_model.frames import STANDARD_GRAVITY_MPS2, quat_from_euler, quat_to_dcm
from rig.autopilot.control import (
    AttitudeController,
    ControlAllocator,
    LowPass2p,
    PositionController,
    RateController,
    thrust_to_attitude,
)
from rig.autopilot.params import Parameters


def test_allocation_is_the_inverse_of_the_effectiveness():
    allocator = ControlAllocator(Parameters())
    torque, thrust = np.array([0.05, -0.03, 0.02]), 0.5
    motors = allocator.allocate(torque, thrust)
    assert allocator.effectiveness @ motors == pytest.approx([*torque, thrust], abs=1e-9)
    assert allocator.unallocated == pytest.approx(np.zeros(4), abs=1e-9)


def test_allocation_signs_follow_px4_motor_order():
    """Roll right speeds up the left motors (1: rear-left, 2: front-left); pitch up the front
    ones (0, 2); positive yaw the CCW ones (0, 1) whose reaction turns the body clockwise."""
    allocator = ControlAllocator(Parameters())
    base = allocator.allocate(np.zeros(3), 0.5)
    assert base == pytest.approx([0.5] * 4)
    roll = allocator.allocate(np.array([0.1, 0, 0]), 0.5) - base
    pitch = allocator.allocate(np.array([0, 0.1, 0]), 0.5) - base
    yaw = allocator.allocate(np.array([0, 0, 0.1]), 0.5) - base
    assert np.sign(roll).tolist() == [-1, 1, 1, -1]
    assert np.sign(pitch).tolist() == [1, -1, 1, -1]
    assert np.sign(yaw).tolist() == [1, 1, -1, -1]


def test_saturated_allocation_keeps_roll_and_reports_unallocated_yaw():
    allocator = ControlAllocator(Parameters())
    motors = allocator.allocate(np.array([0.3, 0.0, 0.5]), 0.9)
    assert motors.min() >= 0.0
    assert motors.max() <= 1.0
    achieved = allocator.effectiveness @ motors
    assert achieved[0] == pytest.approx(0.3, abs=1e-6)  # roll kept whole
    assert allocator.unallocated[2] > 0.1  # yaw gave way first


def test_butterworth_filter_matches_scipy():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((500, 3))
    lpf = LowPass2p(1000.0, 40.0)
    ours = np.array([lpf.apply(sample) for sample in x])
    b, a = signal.butter(2, 40.0, fs=1000.0)
    zi = signal.lfilter_zi(b, a)[:, None] * x[0]
    reference, _ = signal.lfilter(b, a, x, axis=0, zi=zi)
    assert ours == pytest.approx(reference, abs=1e-12)


def test_rate_loop_on_a_known_inertia_reaches_the_setpoint():
    """Roll axis of a rigid body, I·ω̇ = k·torque: PI makes the steady error vanish and the
    response settles without overshoot beyond 20 % (P=0.15, I=0.2, D=0.003 on k/I = 100)."""
    control = RateController(Parameters())
    inertia_gain = 100.0  # rad/s² per unit normalized torque
    omega, dt = 0.0, 1e-3
    history = []
    for _ in range(2000):
        accel = 0.0 if not history else (omega - history[-1]) / dt
        history.append(omega)
        torque = control.update(
            np.array([omega, 0, 0]), np.array([1.0, 0, 0]), np.array([accel, 0, 0]), dt, False
        )
        omega += inertia_gain * torque[0] * dt
    assert max(history) < 1.2
    assert history[-1] == pytest.approx(1.0, abs=0.01)


def test_rate_integrator_frozen_on_ground_and_limited():
    control = RateController(Parameters())
    for _ in range(100):
        control.update(np.zeros(3), np.ones(3), np.zeros(3), 0.01, landed=True)
    assert control.integral == pytest.approx(np.zeros(3))
    for _ in range(10_000):
        control.update(np.zeros(3), np.ones(3), np.zeros(3), 0.01, landed=False)
    assert control.integral == pytest.approx([0.3, 0.3, 0.3])


def test_attitude_error_law_is_px4s():
    """A pure roll error e gives roll rate P·2·sin(e/2); a pure yaw error is weighted and
    the gain compensated, so small yaw errors see MC_YAW_P."""
    control = AttitudeController(Parameters())
    e = math.radians(10)
    rates = control.update(np.array([1.0, 0, 0, 0]), quat_from_euler(e, 0, 0))
    assert rates == pytest.approx([4.0 * 2 * math.sin(e / 2), 0, 0], abs=1e-9)
    small = math.radians(2)
    rates = control.update(np.array([1.0, 0, 0, 0]), quat_from_euler(0, 0, small))
    assert rates[2] == pytest.approx(2.8 * small, rel=2e-3)
    big = control.update(np.array([1.0, 0, 0, 0]), quat_from_euler(math.radians(60), 0, 0))
    assert big[0] == pytest.approx(math.radians(220))  # MC_ROLLRATE_MAX


def test_hover_needs_hover_thrust_and_level_attitude():
    control = PositionController(Parameters())
    thrust, _, _ = control.update(
        np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.full(3, np.nan), (5, 3, 1.5), 0.02
    )
    assert thrust == pytest.approx([0, 0, -0.5])
    q, collective = thrust_to_attitude(thrust, math.radians(30))
    assert collective == pytest.approx(0.5)
    assert q == pytest.approx(quat_from_euler(0, 0, math.radians(30)), abs=1e-12)


def test_horizontal_error_tilts_towards_it_within_the_tilt_limit():
    control = PositionController(Parameters())
    thrust, vel_sp, acc_sp = control.update(
        np.zeros(3), np.zeros(3), np.zeros(3), np.array([100.0, 0, 0]), np.full(3, np.nan),
        (5.0, 3.0, 1.5), 0.02,
    )  # fmt: skip
    assert vel_sp[0] == pytest.approx(5.0)  # horizontal speed limit
    assert acc_sp[0] == pytest.approx(1.8 * 5.0)  # MPC_XY_VEL_P_ACC
    q, _ = thrust_to_attitude(thrust, 0.0)
    body_z = quat_to_dcm(q)[:, 2]
    tilt = math.acos(body_z[2])
    assert tilt == pytest.approx(math.atan(9.0 / STANDARD_GRAVITY_MPS2), abs=1e-6)
    assert body_z[0] < 0  # nose down: thrust points forward
