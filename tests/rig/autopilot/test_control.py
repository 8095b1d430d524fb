"""The control cascade against closed-form cases: allocation inverse, rate loop on a known
inertia, attitude error law, position → thrust mapping."""

import math

import numpy as np
import pytest
from scipy import signal

from quad_model.frames import STANDARD_GRAVITY_MPS2, quat_from_euler, quat_to_dcm
from rig.autopilots.reference.control import (
    AngularVelocityFilter,
    AttitudeController,
    ControlAllocator,
    FilteredDerivative,
    LowPass2p,
    PositionController,
    RateController,
    butterworth2,
    thrust_to_attitude,
)
from rig.autopilots.reference.params import Parameters


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


#: PX4's hexa X (airframe 6001): rotor i's bearing from the nose (deg) and KM sign.
HEXA_X = ((90, -1), (270, 1), (330, -1), (150, 1), (30, 1), (210, -1))
#: PX4's coaxial X8 (12001): rotor i's arm (front, right), height (FRD z) and KM sign; the
#: lower rotor of each arm (4-7) spins against the upper one (0-3).
X8 = (((1, 1), -0.05, 1), ((1, -1), -0.05, -1), ((-1, -1), -0.05, 1), ((-1, 1), -0.05, -1),
      ((1, -1), 0.05, 1), ((1, 1), 0.05, -1), ((-1, 1), 0.05, 1), ((-1, -1), 0.05, -1))  # fmt: skip


def _rotors(rotors):
    """Parameters of a rotor table ``(px, py, pz, km sign)``, KM of PX4's 0.05."""
    params = {"CA_ROTOR_COUNT": len(rotors)}
    for i, (x, y, z, km) in enumerate(rotors):
        params |= {f"CA_ROTOR{i}_PX": x, f"CA_ROTOR{i}_PY": y, f"CA_ROTOR{i}_PZ": z,
                   f"CA_ROTOR{i}_KM": 0.05 * km}  # fmt: skip
    return ControlAllocator(Parameters(params))


def _hexa_x(arm_m=0.5):
    return _rotors([(arm_m * math.cos(math.radians(b)), arm_m * math.sin(math.radians(b)), 0.0, km)
                    for b, km in HEXA_X])  # fmt: skip


def _x8(arm_m=0.35, heights=True):
    return _rotors([(arm_m * x, arm_m * y, z if heights else 0.0, km) for (x, y), z, km in X8])


#: The hexa X's normalized roll and pitch columns in closed form: the effectiveness rows
#: (−py, px) are orthogonal, so the pseudo-inverse's columns are the rows over their squared
#: norms (3r² each); PX4's scale is the larger RMS over half the rotors taking part, the
#: pitch column's (4 rotors): roll entries √(2/3) and √(1/6), pitch 1/√2.
HEXA_ROLL = np.array([-1, 1, 0.5, -0.5, -0.5, 0.5]) * math.sqrt(2 / 3)
HEXA_PITCH = np.array([0, 0, 1, -1, 1, -1]) / math.sqrt(2)
HEXA_YAW = np.array([km for _, km in HEXA_X], dtype=float)


@pytest.mark.parametrize("arm_m", [0.25, 0.5])
def test_hexa_x_pure_demands_give_the_pseudo_inverses_motor_pattern(arm_m):
    """Pure roll, pitch, yaw and thrust on PX4's hexa X: the normalized columns above,
    whatever the arm length; yaw ±1 by the KM signs, thrust 1 on every rotor."""
    allocator = _hexa_x(arm_m)
    assert allocator.motor_count == 6
    for torque, pattern in (([0.1, 0, 0], HEXA_ROLL), ([0, 0.1, 0], HEXA_PITCH),
                            ([0, 0, 0.1], HEXA_YAW)):  # fmt: skip
        motors = allocator.allocate(np.array(torque, dtype=float), 0.5)
        np.testing.assert_allclose(motors, 0.5 + 0.1 * pattern, atol=1e-9)
        assert allocator.unallocated == pytest.approx(np.zeros(4), abs=1e-9)
    np.testing.assert_allclose(allocator.allocate(np.zeros(3), 0.3), 0.3, atol=1e-12)


def test_x8_pairs_share_roll_and_pitch_and_split_yaw_whatever_their_heights():
    """The coaxial X8: eight rotors on four arms, every roll and pitch entry ±1/√2 (the
    same for a pair on one arm), yaw ±1 opposite within a pair; the rotors' heights (PZ)
    change nothing, as for any rotor whose thrust is along z (r × a has no PZ term)."""
    allocator, flat = _x8(), _x8(heights=False)
    np.testing.assert_allclose(allocator.mix, flat.mix, atol=1e-12)
    arms = np.array([arm for arm, _, _ in X8], dtype=float)
    km = np.array([k for *_, k in X8], dtype=float)
    roll, pitch = -arms[:, 1] / math.sqrt(2), arms[:, 0] / math.sqrt(2)
    for torque, pattern in (([0.1, 0, 0], roll), ([0, 0.1, 0], pitch), ([0, 0, 0.1], km)):
        motors = allocator.allocate(np.array(torque, dtype=float), 0.5)
        np.testing.assert_allclose(motors, 0.5 + 0.1 * pattern, atol=1e-9)
    for upper, lower in ((0, 5), (1, 4), (2, 7), (3, 6)):
        assert allocator.mix[upper, :2] == pytest.approx(allocator.mix[lower, :2], abs=1e-12)
        assert allocator.mix[upper, 2] == pytest.approx(-allocator.mix[lower, 2], abs=1e-12)


def test_saturation_at_high_thrust_lowers_the_thrust_and_keeps_roll():
    """Hexa X, thrust 0.9 and roll 0.3: motor 1 would need 0.9 + 0.3·√(2/3) = 1.145. PX4
    (airmode off) lowers the thrust until it fits: roll whole, thrust 1 − 0.3·√(2/3)."""
    allocator = _hexa_x()
    motors = allocator.allocate(np.array([0.3, 0.0, 0.0]), 0.9)
    thrust = 1.0 - 0.3 * math.sqrt(2 / 3)
    np.testing.assert_allclose(motors, thrust + 0.3 * HEXA_ROLL, atol=1e-9)
    assert allocator.unallocated == pytest.approx([0, 0, 0, 0.9 - thrust], abs=1e-9)


def test_saturation_at_low_thrust_keeps_the_thrust_and_cuts_roll():
    """Hexa X, thrust 0.1 and roll 0.3: motor 0 would need 0.1 − 0.3·√(2/3) < 0. The
    thrust may not rise (airmode off), so roll gives way to what the thrust leaves: the
    most loaded rotor at 0, roll 0.1/√(2/3)."""
    allocator = _hexa_x()
    motors = allocator.allocate(np.array([0.3, 0.0, 0.0]), 0.1)
    roll = 0.1 / math.sqrt(2 / 3)
    np.testing.assert_allclose(motors, 0.1 + roll * HEXA_ROLL, atol=1e-9)
    assert motors[0] == pytest.approx(0.0, abs=1e-12)
    assert allocator.unallocated == pytest.approx([0.3 - roll, 0, 0, 0], abs=1e-9)


@pytest.mark.parametrize(("yaw", "kept"), [(0.2, 0.2), (0.3, 0.2)])
def test_yaw_may_reach_15_percent_above_full_before_the_thrust_gives_way(yaw, kept):
    """X8, thrust 0.95 and yaw on top: PX4 lets yaw fill the outputs up to 1.15 (giving
    way beyond, here to 1.15 − 0.95 = 0.2), then lowers the thrust until they fit in 1."""
    allocator = _x8()
    km = np.array([k for *_, k in X8], dtype=float)
    motors = allocator.allocate(np.array([0.0, 0.0, yaw]), 0.95)
    thrust = 1.0 - kept
    np.testing.assert_allclose(motors, thrust + kept * km, atol=1e-9)
    assert allocator.unallocated == pytest.approx([0, 0, yaw - kept, 0.95 - thrust], abs=1e-9)


def test_butterworth_filter_matches_scipy():
    rng = np.random.default_rng(0)
    x = rng.standard_normal((500, 3))
    lpf = LowPass2p(1000.0, 40.0)
    ours = np.array([lpf.apply(sample) for sample in x])
    b, a = signal.butter(2, 40.0, fs=1000.0)
    zi = signal.lfilter_zi(b, a)[:, None] * x[0]
    reference, _ = signal.lfilter(b, a, x, axis=0, zi=zi)
    assert ours == pytest.approx(reference, abs=1e-12)


@pytest.mark.parametrize(
    ("sample_rate_hz", "cutoff_hz"), [(1000.0, 30.0), (250.0, 40.0), (400.0, 1.0), (1000.0, 499.0)]
)
def test_butterworth_design_is_scipys_with_unit_dc_gain_and_minus_3_db_at_the_cutoff(
    sample_rate_hz, cutoff_hz
):
    b, a = butterworth2(cutoff_hz, sample_rate_hz)
    b_scipy, a_scipy = signal.butter(2, cutoff_hz, fs=sample_rate_hz)
    assert b == pytest.approx(b_scipy, rel=1e-12, abs=1e-15)
    assert a == pytest.approx(a_scipy, rel=1e-12, abs=1e-15)
    _, (dc, at_cutoff) = signal.freqz(b, a, worN=[0.0, cutoff_hz], fs=sample_rate_hz)
    assert abs(dc) == pytest.approx(1.0, abs=1e-12)
    assert abs(at_cutoff) == pytest.approx(math.sqrt(0.5), abs=1e-9)  # prewarped: exact


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


@pytest.mark.parametrize(("cutoff_hz", "dt"), [(2.0, 1e-3), (2.0, 4e-3), (0.0, 1e-3)])
def test_yaw_torque_is_low_passed_at_mc_yaw_tq_cutoff(cutoff_hz, dt):
    """PX4's first-order AlphaFilter on the yaw torque alone: after n steps of a unit yaw
    torque, 1 − (1 − α)ⁿ with α = dt/(dt + 1/(2π·f_c)); roll and pitch pass unfiltered, and
    a cutoff of 0 turns it off. P only, so the unfiltered torque is the error itself."""
    gains = {"MC_ROLLRATE_I": 0.0, "MC_PITCHRATE_I": 0.0, "MC_YAWRATE_I": 0.0,
             "MC_ROLLRATE_D": 0.0, "MC_PITCHRATE_D": 0.0, "MC_ROLLRATE_P": 0.1,
             "MC_PITCHRATE_P": 0.1, "MC_YAWRATE_P": 0.1, "MC_YAW_TQ_CUTOFF": cutoff_hz}  # fmt: skip
    control = RateController(Parameters(gains))
    steps = round(0.25 / dt)
    for _ in range(steps):
        torque = control.update(np.zeros(3), np.full(3, 10.0), np.zeros(3), dt, False)
    alpha = dt / (dt + 1.0 / (2.0 * math.pi * cutoff_hz)) if cutoff_hz else 1.0
    assert torque[:2] == pytest.approx([1.0, 1.0], abs=1e-12)
    assert torque[2] == pytest.approx(1.0 - (1.0 - alpha) ** steps, abs=1e-12)
    if cutoff_hz:  # a quarter second at 2 Hz is about three time constants (0.080 s): 0.96
        assert 0.9 < torque[2] < 0.99
    control.reset_integral()
    assert control.update(np.zeros(3), np.zeros(3), np.zeros(3), dt, False)[2] == 0.0


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
        np.zeros(3), np.zeros(3), np.zeros(3), np.full(3, np.nan), (5, 3, 1.5), 0.02
    )
    assert thrust == pytest.approx([0, 0, -0.5])
    q, collective = thrust_to_attitude(thrust, math.radians(30))
    assert collective == pytest.approx(0.5)
    assert q == pytest.approx(quat_from_euler(0, 0, math.radians(30)), abs=1e-12)


def test_horizontal_error_tilts_towards_it_within_the_tilt_limit():
    control = PositionController(Parameters())
    thrust, vel_sp, acc_sp = control.update(
        np.zeros(3), np.zeros(3), np.array([100.0, 0, 0]), np.full(3, np.nan),
        (5.0, 3.0, 1.5), 0.02,
    )  # fmt: skip
    assert vel_sp[0] == pytest.approx(5.0)  # horizontal speed limit
    assert acc_sp[0] == pytest.approx(1.8 * 5.0)  # MPC_XY_VEL_P_ACC
    q, _ = thrust_to_attitude(thrust, 0.0)
    body_z = quat_to_dcm(q)[:, 2]
    tilt = math.acos(body_z[2])
    assert tilt == pytest.approx(math.atan(9.0 / STANDARD_GRAVITY_MPS2), abs=1e-6)
    assert body_z[0] < 0  # nose down: thrust points forward


def test_filtered_derivative_of_a_ramp_is_a_first_order_step_to_its_slope():
    """A ramp of slope s: the first call has no derivative (0), then every difference
    quotient is s and PX4's BlockLowPass (a = b/(1+b), b = 2π·f_c·dt) approaches it as the
    discrete first-order step response s·(1 − (1/(1+b))ⁿ) after n quotients."""
    dt, cutoff_hz = 0.02, 5.0
    slope = np.array([1.5, -0.5, 2.0])
    derivative = FilteredDerivative(cutoff_hz)
    assert derivative.update(np.zeros(3), dt) == pytest.approx(np.zeros(3), abs=0.0)
    b = 2 * math.pi * cutoff_hz * dt
    for n in range(1, 51):
        value = derivative.update(slope * n * dt, dt)
        assert value == pytest.approx(slope * (1 - (1 / (1 + b)) ** n), rel=1e-9)
    assert value == pytest.approx(slope, rel=1e-6)  # settled: the slope itself


def test_filtered_derivative_without_cutoff_is_the_difference_quotient_and_resets():
    derivative = FilteredDerivative(0.0)  # MPC_VELD_LP = 0: no low-pass
    derivative.update(np.array([1.0, 2.0, 3.0]), 0.01)
    assert derivative.update(np.array([1.5, 1.0, 3.0]), 0.01) == pytest.approx([50, -100, 0])
    derivative.reset()
    assert derivative.update(np.array([9.0, 9.0, 9.0]), 0.01) == pytest.approx(np.zeros(3))
    assert derivative.update(np.array([9.0, 9.0, 9.1]), 0.01) == pytest.approx([0, 0, 10])


def _gyro_gain(angular: AngularVelocityFilter, frequency_hz: float, rate_hz: float,
               start_us: int) -> tuple[float, float]:  # fmt: skip
    """Steady-state amplitude of the filtered rate and angular acceleration for a unit sine
    sampled at ``rate_hz`` from ``start_us`` on (the last second of four)."""
    period_us = round(1e6 / rate_hz)
    rates, accels = [], []
    for k in range(4 * round(rate_hz)):
        time_us = start_us + k * period_us
        angular.update(np.full(3, math.sin(2 * math.pi * frequency_hz * time_us * 1e-6)), time_us)
        rates.append(angular.rates_radps[0])
        accels.append(angular.angular_accel_radps2[0])
    last = round(rate_hz)
    return max(np.abs(rates[-last:])), max(np.abs(accels[-last:]))


@pytest.mark.parametrize("rate_hz", [250, 1000])
def test_gyro_filters_are_designed_for_the_measured_imu_rate(rate_hz):
    """At its cutoff a 2nd-order Butterworth passes 1/√2 of a sine, at the IMU rate the
    timestamps show (the first frame at one period, as in a lockstep run: no earlier time to
    measure from). Designed for 1 kHz but run at 250 Hz, the 40 Hz gyro cutoff would act at
    10 Hz, pass 0.06 of a 40 Hz sine, and its lag made the rate loop limit-cycle."""
    params = Parameters()
    angular = AngularVelocityFilter(params)
    period_us = 1_000_000 // rate_hz
    cutoff_hz = params["IMU_GYRO_CUTOFF"]
    gain, _ = _gyro_gain(angular, cutoff_hz, rate_hz, start_us=period_us)
    assert angular.sample_rate_hz == rate_hz
    # the sine's peak falls between samples: up to 1 − cos(π·f/fs) = 3 % low at 250 Hz
    assert gain == pytest.approx(1 / math.sqrt(2), rel=0.04)
    # the D-term's angular acceleration: a sine of ω rad/s² at IMU_DGYRO_CUTOFF, through the
    # same Butterworth, after the difference quotient's own gain sin(πf/fs)/(πf/fs)
    dgyro_hz = params["IMU_DGYRO_CUTOFF"]
    angular = AngularVelocityFilter(params)
    _, accel_gain = _gyro_gain(angular, dgyro_hz, rate_hz, start_us=period_us)
    x = math.pi * dgyro_hz / rate_hz
    assert accel_gain == pytest.approx(2 * math.pi * dgyro_hz / math.sqrt(2) * math.sin(x) / x,
                                       rel=0.04)  # fmt: skip


def test_gyro_filters_follow_a_changed_imu_rate_within_one_percent():
    """PX4's CheckFilters: a first interval that misleads (1 ms, then 4 ms frames) is
    corrected once a window of intervals shows the true rate; a 0.5 % drift is not."""
    params = Parameters()
    angular = AngularVelocityFilter(params)
    angular.update(np.zeros(3), 1000)
    angular.update(np.zeros(3), 2000)
    assert angular.sample_rate_hz == 1000
    gain, _ = _gyro_gain(angular, params["IMU_GYRO_CUTOFF"], 250, start_us=6000)
    assert angular.sample_rate_hz == pytest.approx(250)
    assert gain == pytest.approx(1 / math.sqrt(2), rel=0.04)
    for k in range(300):  # after a 1 s gap, 4020 µs frames: 248.8 Hz, within 1 % of it
        angular.update(np.zeros(3), 5_000_000 + k * 4020)
    assert angular.sample_rate_hz == pytest.approx(250)
    for k in range(1, 300):  # 4100 µs: 243.9 Hz, off by 2.4 %
        angular.update(np.zeros(3), 7_000_000 + k * 4100)
    assert angular.sample_rate_hz == pytest.approx(1e6 / 4100)
