"""The pilot's sticks: MANUAL_CONTROL decoded, PX4's stick shaping, Position and Altitude
modes' set-points, the take-off ramp, and the modes' requirements and failsafes."""

import math

import numpy as np
import pytest

from quad_model.frames import STANDARD_GRAVITY_MPS2
from rig.autopilots.reference.flight_controller import FlightController
from rig.autopilots.reference.manual import (
    ManualTask,
    Sticks,
    deadzone,
    expo,
    expo_deadzone,
    sticks_from_manual_control,
)
from rig.autopilots.reference.navigator import NavState, nav_state_from_custom
from rig.autopilots.reference.params import Parameters
from rig.mavlink.px4_api import mavlink
from tests.rig.autopilot.test_optical_flow import _fly_still

DT_S = 0.02


@pytest.mark.parametrize(
    ("xyzr", "expected"),
    [
        ((0, 0, 0, 0), (0.0, 0.0, 0.0, -1.0)),  # roll, pitch, yaw, throttle
        ((0, 0, 500, 0), (0.0, 0.0, 0.0, 0.0)),
        ((1000, -500, 1000, 250), (-0.5, 1.0, 0.25, 1.0)),
        ((-2000, 1500, 1200, -1000), (1.0, -1.0, -1.0, 1.0)),  # held at the stops
    ],
)
def test_manual_control_decodes_as_px4_reads_it(xyzr, expected):
    sticks = sticks_from_manual_control(*xyzr, time_us=7)
    assert (sticks.roll, sticks.pitch, sticks.yaw, sticks.throttle) == pytest.approx(expected)
    assert sticks.time_us == 7


@pytest.mark.parametrize(
    ("value", "dz", "out"),
    [(0.05, 0.1, 0.0), (-0.1, 0.1, 0.0), (0.55, 0.1, 0.5), (-1.0, 0.1, -1.0), (1.5, 0.1, 1.0),
     (0.3, 0.0, 0.3)],
)  # fmt: skip
def test_deadzone_is_px4s(value, dz, out):
    """(x − sign(x)·dz) / (1 − dz) outside ±dz, 0 inside, the input held to ±1."""
    assert deadzone(value, dz) == pytest.approx(out)


@pytest.mark.parametrize(
    ("value", "e", "out"),
    [(0.5, 0.6, 0.4 * 0.5 + 0.6 * 0.125), (-1.0, 0.6, -1.0), (0.5, 0.0, 0.5), (0.5, 1.0, 0.125),
     (2.0, 0.6, 1.0)],
)  # fmt: skip
def test_expo_is_px4s(value, e, out):
    """(1 − e)·x + e·x³."""
    assert expo(value, e) == pytest.approx(out)


def test_expo_deadzone_is_the_deadzone_then_the_expo():
    x = (0.8 - 0.1) / 0.9
    assert expo_deadzone(0.8, 0.6, 0.1) == pytest.approx(0.4 * x + 0.6 * x**3)


def _sticks(roll=0.0, pitch=0.0, yaw=0.0, throttle=0.0):
    return Sticks(roll, pitch, yaw, throttle, time_us=0)


def _task(position_mode=True, on_ground=False, position=(1.0, 2.0, -10.0)):
    task = ManualTask(Parameters())
    task.activate(np.array(position), position_mode, on_ground)
    return task


def _step(task, sticks, velocity=(0.0, 0.0, 0.0), yaw=0.0, height=20.0, position=(1.0, 2.0, -10.0)):
    return task.update(sticks, np.array(position), np.array(velocity), yaw, height, DT_S)


def test_position_mode_full_forward_is_mpc_vel_manual_in_the_heading_frame():
    """Facing east, full pitch forward: 10 m/s (MPC_VEL_MANUAL) east, no position lock."""
    sp = _step(_task(), _sticks(pitch=1.0), yaw=math.pi / 2)
    assert sp.velocity_ned_mps[:2] == pytest.approx((0.0, 10.0), abs=1e-9)
    assert np.isnan(sp.position_ned_m[:2]).all()
    assert sp.velocity_limits_mps[0] == 10.0


def test_position_mode_stick_xy_is_limited_to_unit_length():
    sp = _step(_task(), _sticks(roll=1.0, pitch=1.0))
    assert math.hypot(*sp.velocity_ned_mps[:2]) == pytest.approx(10.0)


def test_position_mode_half_stick_follows_deadzone_and_expo():
    sp = _step(_task(), _sticks(roll=0.5))
    assert sp.velocity_ned_mps[1] == pytest.approx(10.0 * expo_deadzone(0.5, 0.6, 0.1))


def test_centred_sticks_brake_then_lock_the_position_where_it_stopped():
    """Centred while faster than MPC_HOLD_MAX_XY (0.8 m/s): a zero velocity set-point and no
    position; slower: the position is locked there, and kept."""
    task = _task()
    _step(task, _sticks(pitch=1.0))
    braking = _step(task, _sticks(), velocity=(2.0, 0.0, 0.0), position=(5.0, 2.0, -10.0))
    assert np.isnan(braking.position_ned_m[:2]).all()
    assert braking.velocity_ned_mps[:2] == pytest.approx((0.0, 0.0))
    locked = _step(task, _sticks(), velocity=(0.5, 0.0, 0.0), position=(6.0, 2.0, -10.0))
    assert locked.position_ned_m[:2] == pytest.approx((6.0, 2.0))
    kept = _step(task, _sticks(), velocity=(0.1, 0.0, 0.0), position=(6.3, 2.0, -10.0))
    assert kept.position_ned_m[:2] == pytest.approx((6.0, 2.0))


@pytest.mark.parametrize(
    ("throttle", "height_m", "vz"),
    [(1.0, 20.0, -3.0),  # MPC_Z_VEL_MAX_UP
     (-1.0, 20.0, 1.5),  # MPC_Z_VEL_MAX_DN
     (1.0, 1.0, -1.5),  # near the ground: MPC_TKO_SPEED
     (-1.0, 1.0, 0.7),  # MPC_LAND_SPEED
     (-1.0, 7.5, 0.7 + 0.5 * (1.5 - 0.7)),  # halfway from MPC_LAND_ALT2 to ALT1
     (0.5, 20.0, -3.0 * expo_deadzone(0.5, 0.6, 0.1))],
)  # fmt: skip
def test_throttle_stick_is_a_vertical_speed(throttle, height_m, vz):
    sp = _step(_task(), _sticks(throttle=throttle), height=height_m)
    assert sp.velocity_ned_mps[2] == pytest.approx(vz)
    assert math.isnan(sp.position_ned_m[2])


def test_centred_throttle_holds_the_height():
    sp = _step(_task(position=(0.0, 0.0, -4.0)), _sticks(), position=(0.0, 0.0, -4.2))
    assert sp.position_ned_m[2] == pytest.approx(-4.0)  # locked at activation
    assert sp.velocity_ned_mps[2] == 0.0


def test_yaw_stick_is_a_rate_up_to_mpc_man_y_max_and_centred_holds_the_heading():
    task = _task()
    for _ in range(100):  # 2 s: many MPC_MAN_Y_TAU (0.08 s)
        sp = _step(task, _sticks(yaw=1.0), yaw=0.3)
    assert sp.yawspeed_radps == pytest.approx(math.radians(150.0), rel=1e-6)
    assert sp.yaw_rad == 0.3  # no heading set-point: the current one
    for _ in range(100):
        sp = _step(task, _sticks(), yaw=1.2)
    assert abs(sp.yawspeed_radps) < 0.001
    held = sp.yaw_rad
    assert _step(task, _sticks(), yaw=1.25).yaw_rad == held


def test_altitude_mode_sticks_are_a_tilt_up_to_mpc_man_tilt_max():
    """Full right roll: the acceleration of a 35° tilt to the right, no horizontal position
    or velocity control (PX4's StickTiltXY)."""
    sp = _step(_task(position_mode=False), _sticks(roll=1.0))
    accel = math.tan(math.radians(35.0)) * STANDARD_GRAVITY_MPS2
    assert sp.acceleration_ned_mps2[:2] == pytest.approx((0.0, accel))
    assert np.isnan(sp.velocity_ned_mps[:2]).all()
    assert np.isnan(sp.position_ned_m[:2]).all()


def test_takeoff_ramp_lifts_the_up_limit_from_minus_g_over_the_gain_in_mpc_tko_ramp_t():
    task = _task(on_ground=True)
    start = -STANDARD_GRAVITY_MPS2 / 4.0  # MPC_Z_VEL_P_ACC
    first = _step(task, _sticks(throttle=0.8)).velocity_limits_mps[1]
    assert first == pytest.approx(start + DT_S / 3.0 * (3.0 - start))
    for _ in range(round(3.0 / DT_S)):
        up = _step(task, _sticks(throttle=0.8)).velocity_limits_mps[1]
    assert up == 3.0
    assert ManualTask.wants_takeoff(_sticks(throttle=0.31))
    assert not ManualTask.wants_takeoff(_sticks(throttle=0.3))


def test_do_set_mode_knows_altitude_and_position_but_not_manual():
    assert nav_state_from_custom(2, 0) == NavState.ALTCTL
    assert nav_state_from_custom(3, 0) == NavState.POSCTL
    assert nav_state_from_custom(1, 0) is None


def test_stick_modes_need_their_estimate_and_the_sticks():
    fc = FlightController(Parameters({"ATT_MAG_DECL_A": 0}))
    assert fc.set_mode(NavState.ALTCTL).reason == "Switching to ALTCTL denied: no height estimate"
    refused = fc.set_mode(NavState.POSCTL).reason
    assert refused == "Switching to POSCTL denied: no position estimate"
    k = _fly_still(fc, 1, 3.0, 150)  # flow and the rangefinder: a local position
    for mode in (NavState.POSCTL, NavState.ALTCTL):
        refused = fc.set_mode(mode).reason
        assert refused == f"Switching to {mode.name} denied: no manual control input"
    fc.set_sticks(Sticks(0.0, 0.0, 0.0, -1.0, fc.time_us))
    assert fc.set_mode(NavState.POSCTL).result == mavlink.MAV_RESULT_ACCEPTED
    k = _fly_still(fc, k, 0.6, 150)  # longer than COM_RC_LOSS_T (0.5 s)
    assert not fc.sticks_present()
    assert fc.arm().reason == "Arming denied: no manual control input"


def test_sticks_lost_when_armed_in_position_mode_land():
    fc = FlightController(Parameters({"ATT_MAG_DECL_A": 0}))
    k = _fly_still(fc, 1, 3.0, 150)
    fc.set_sticks(Sticks(0.0, 0.0, 0.0, -1.0, fc.time_us))
    assert fc.set_mode(NavState.POSCTL).result == mavlink.MAV_RESULT_ACCEPTED
    assert fc.arm().result == mavlink.MAV_RESULT_ACCEPTED
    _fly_still(fc, k, 0.6, 150)
    assert fc.nav_state == NavState.AUTO_LAND
    assert (mavlink.MAV_SEVERITY_CRITICAL, "Failsafe: manual control lost, Land") in list(
        fc.status_messages
    )
