"""PX4 flies the bundled hexa and the coaxial X8 through the RTL chips at IMU 1 kHz, on every
release: take-off, hover, a square in offboard position set-points, landing. The rig hands
PX4 the geometry (CA_ROTOR_COUNT, CA_ROTORn_PX/PY/PZ/KM) and the outputs of motors 5-8, and
the PWM capture carries every motor back to the model. A hexa that loses a motor reacts as
PX4's control allocation says it will."""

import numpy as np
import pytest
import pyulog

from quad_model import load_vehicle
from tests.rig.px4_flights import Hover, fly_px4, inside, takeoff_hover_land, topic

pytestmark = [pytest.mark.closed_loop, pytest.mark.cosim]

VEHICLES = ("f550_hexa", "auriol_x8")
#: How close each holds, in m: PX4's height estimate to its set-point in the hover, the truth
#: to the set-point, the square's track to each corner. The hexa holds as the quads do
#: (test_px4_flights.py; measured on v1.14 and v1.17: 0.04, 0.11 and 0.14 m). The X8 flies
#: with PX4's default tuning, a 2 kg quad's, through the hover vibration its file extrapolates
#: from the ground run (gyro σ 0.27 rad/s at the IMU): PX4's estimate holds within 0.32 m,
#: the truth swings by up to 0.92 m (EKF2 takes its height from the GPS and learns the
#: accelerometer's bias slowly) and it overshoots corners by up to 0.73 m.
TOLERANCE_M = {
    "f550_hexa": {"estimate": 0.15, "truth": 0.2, "corner": 0.5},
    "auriol_x8": {"estimate": 0.45, "truth": 1.2, "corner": 1.0},
}
ALTITUDE_M = 2.5
#: The square's corners (PX4's local frame, m north and east) and when each is commanded.
CORNERS_M = ((4.0, 0.0), (4.0, 4.0), (0.0, 4.0), (0.0, 0.0))
LEG_S = 7.0
#: PX4 climbs from about 14.5 s (v1.15 on close the last metre slowly): the hover is judged
#: over 21-27 s, as the quads' (test_px4_flights.py), then the square begins.
HOVER_S = (21.0, 27.0)
SQUARE_START_S = 27.5
LAND_S = SQUARE_START_S + LEG_S * len(CORNERS_M)


def _square_flight() -> list[dict]:
    arm_and_takeoff = takeoff_hover_land(10.0, LAND_S, ALTITUDE_M)
    legs = [{"at_s": SQUARE_START_S + LEG_S * k, "action": "goto",
             "position_ned_m": [north, east, -ALTITUDE_M]}
            for k, (north, east) in enumerate(CORNERS_M)]  # fmt: skip
    return arm_and_takeoff[:2] + legs + arm_and_takeoff[2:]


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_px4_flies_a_hexa_and_an_x8_through_the_rtl_chips(
    tmp_path, free_instance, any_px4, vehicle
):
    """Over 6 s of hover PX4 holds its height estimate near its set-point and the truth
    near it; the second half of each leg of the 4 m square passes its corner (TOLERANCE_M);
    every motor ran (none idle in the hover); it lands and disarms."""
    rotors = load_vehicle(vehicle).propulsion.rotor_count
    result = fly_px4(tmp_path, free_instance, any_px4.root, vehicle, LAND_S + 16.0,
                     _square_flight(), vehicle=vehicle, sensor_layer="rtl",
                     rates={"imu_hz": 1000})  # fmt: skip
    rig_log, px4_log = pyulog.ULog(str(result.rig_log)), pyulog.ULog(str(result.autopilot_log))
    assert px4_log.initial_parameters["CA_ROTOR_COUNT"] == rotors
    hover = Hover(rig_log, px4_log, ground_s=(7.0, 9.5), window_s=HOVER_S)
    tolerance = TOLERANCE_M[vehicle]
    assert np.abs(hover.estimate_minus_setpoint_m).max() < tolerance["estimate"]
    assert np.abs(hover.truth_minus_setpoint_m).max() < tolerance["truth"]
    truth_t, truth = topic(rig_log, "vehicle_local_position_groundtruth")
    est_t, est = topic(px4_log, "vehicle_local_position")
    ground = inside(est_t, (7.0, 9.5))
    offset = {axis: np.mean(est[axis][ground] - np.interp(est_t[ground], truth_t, truth[axis]))
              for axis in "xy"}  # fmt: skip
    for k, corner in enumerate(CORNERS_M):
        leg = inside(
            truth_t, (SQUARE_START_S + LEG_S * (k + 0.5), SQUARE_START_S + LEG_S * (k + 1))
        )
        reached = np.column_stack([truth["x"][leg] + offset["x"], truth["y"][leg] + offset["y"]])
        error = np.linalg.norm(reached - corner, axis=1).min()
        assert error < tolerance["corner"], f"corner {k} {corner} missed by {error:.2f} m"
    motors_t, motors = topic(rig_log, "actuator_outputs")
    hovering = inside(motors_t, HOVER_S)
    assert set(motors["noutputs"]) == {rotors}
    widths = np.array([motors[f"output[{i}]"][hovering] for i in range(rotors)])
    assert (widths > 1100).all(), "a motor idled in the hover"
    _, armed = topic(px4_log, "actuator_armed")
    assert not armed["armed"][-1]
    assert abs(truth["z"][-1]) < 0.05


def test_a_hexa_that_loses_a_motor_keeps_flying_without_yaw(tmp_path, free_instance, px4_dir):
    """Motor 0 of the hexa lost in the hover: PX4 (CA_FAILURE_MODE 0, no ESC telemetry to
    detect it) keeps the dead motor in its allocation, and its sequential desaturation gives
    up yaw first. The hexa drops and drifts, then holds its position on five motors while it
    turns about its yaw axis without end; PX4 raises no failsafe and stays in its mode."""
    loss_s = 25.0
    result = fly_px4(tmp_path, free_instance, px4_dir, "hexa_motor_loss", 40.0,
                     takeoff_hover_land(10.0, 999.0, ALTITUDE_M)[:2], vehicle="f550_hexa",
                     sensor_layer="rtl", rates={"imu_hz": 1000},
                     faults=[{"kind": "motor_loss", "motor": 0, "start_s": loss_s}])  # fmt: skip
    rig_log, px4_log = pyulog.ULog(str(result.rig_log)), pyulog.ULog(str(result.autopilot_log))
    truth_t, truth = topic(rig_log, "vehicle_local_position_groundtruth")
    before = inside(truth_t, (loss_s - 3.0, loss_s))
    after, held = truth_t > loss_s, truth_t > loss_s + 8.0
    assert -truth["z"][after].min() > 1.5  # it dropped, but not to the ground
    home = np.array([truth["x"][before].mean(), truth["y"][before].mean()])
    drift = np.hypot(truth["x"][held] - home[0], truth["y"][held] - home[1])
    assert drift.max() < 1.0, f"drifted {drift.max():.2f} m from its hover on five motors"
    attitude_t, attitude = topic(rig_log, "vehicle_attitude_groundtruth")
    q = np.array([attitude[f"q[{k}]"] for k in range(4)])
    tilt_deg = np.degrees(np.arccos(np.clip(1 - 2 * (q[1] ** 2 + q[2] ** 2), -1, 1)))
    assert tilt_deg[attitude_t > loss_s + 8.0].max() < 10.0
    yaw = np.unwrap(np.arctan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2)))
    turning = np.diff(yaw[attitude_t > loss_s + 5.0])
    assert abs(turning.sum()) > np.radians(45)  # about 5°/s on v1.17
    assert (np.sign(turning) == np.sign(turning.sum())).mean() > 0.9  # one way, without end
    status_t, status = topic(px4_log, "vehicle_status")
    flying = status_t > loss_s
    assert not status["failsafe"][flying].any()
    assert set(status["nav_state"][flying]) == set(
        status["nav_state"][inside(status_t, (20.0, loss_s))]
    )
