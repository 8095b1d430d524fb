"""The reference autopilot flying without GPS, on the PMW3901's optical flow and the
LIDAR-Lite's height, through the rig (the chips' transaction-level models).

Every position judged comes from the rig's ground truth (rig.ulg); the autopilot's log gives
its heading, whose north is magnetic here (no GPS, so no declination from the WMM).
"""

import dataclasses
import math

import numpy as np
import pytest
import pyulog

from quad_model.frames import euler_from_quat
from rig.scenarios.scenario import load_scenario
from tests.rig.flights import fly

pytestmark = pytest.mark.closed_loop

HOVER_M = 2.5
#: The hold after the climb: from the end of the take-off to the first corner.
HOLD_S = (10.0, 30.0)
#: Offboard corners of a 2 m square in the autopilot's local frame (NED, m), 6 s apart.
CORNERS = ((2.0, 0.0), (2.0, 2.0), (0.0, 2.0), (0.0, 0.0))
CORNER_START_S = 30.0
CORNER_S = 6.0
LAND_S = CORNER_START_S + CORNER_S * len(CORNERS)
#: The brief's bounds: the hold within ±0.3 m of the take-off point (x and y), each corner
#: reached within 0.5 m.
HOLD_BOUND_M = 0.3
CORNER_BOUND_M = 0.5


def _commands() -> list[dict]:
    corners = [
        {
            "at_s": CORNER_START_S + CORNER_S * i,
            "action": "goto",
            "position_ned_m": [x, y, -HOVER_M],
        }
        for i, (x, y) in enumerate(CORNERS)
    ]
    return [{"at_s": 2.0, "action": "arm"},
            {"at_s": 2.1, "action": "takeoff", "altitude_m": HOVER_M},
            *corners,
            {"at_s": LAND_S, "action": "land"}]  # fmt: skip


def _series(log: pyulog.ULog, topic: str, *fields: str) -> tuple[np.ndarray, ...]:
    data = log.get_dataset(topic).data
    return (data["timestamp"] / 1e6, *(np.asarray(data[f], dtype=float) for f in fields))


def _yaw(log: pyulog.ULog, topic: str) -> tuple[np.ndarray, np.ndarray]:
    t, *q = _series(log, topic, "q[0]", "q[1]", "q[2]", "q[3]")
    return t, np.array([euler_from_quat(np.array(row))[2] for row in zip(*q, strict=True)])


def _corner_errors(rig_log, autopilot_log, start, first_s, leg_s) -> list[float]:
    """How far the truth is from each corner at the end of its leg, in the autopilot's own
    frame (its north is magnetic without GPS: the truth is turned by its heading error)."""
    t, x, y = _series(rig_log, "vehicle_local_position_groundtruth", "x", "y")
    t_true, yaw_true = _yaw(rig_log, "vehicle_attitude_groundtruth")
    t_est, yaw_est = _yaw(autopilot_log, "vehicle_attitude")
    errors = []
    for i, corner in enumerate(CORNERS):
        at = first_s + leg_s * (i + 1) - 0.05
        k = np.searchsorted(t, at)
        heading = yaw_est[np.searchsorted(t_est, at)] - yaw_true[np.searchsorted(t_true, at)]
        c, s = math.cos(heading), math.sin(heading)
        moved = np.array([x[k], y[k]]) - start
        in_frame = np.array([c * moved[0] - s * moved[1], s * moved[0] + c * moved[1]])
        errors.append(float(np.hypot(*(in_frame - corner))))
    return errors


def test_without_gps_it_holds_and_flies_a_square_on_optical_flow(tmp_path):
    """F450, `gps = false`, `optical_flow = true`, `rangefinder = true`, sensor_layer "tlm":
    it arms, takes off to 2.5 m, holds 20 s within ±0.3 m of its take-off point, flies a
    2 m square of offboard position targets (each corner within 0.5 m after 6 s; the
    square judged in the autopilot's frame, the truth turned by its heading error), lands
    and disarms, with no failsafe. Measured: the hold within 0.07 m (x) and 0.12 m (y),
    the corners within 0.14-0.37 m."""
    scenario = {"name": "flow_square", "vehicle": "f450_high_precision",
                "duration_s": LAND_S + 14.0, "seed": 3, "sensor_layer": "tlm", "gps": False,
                "optical_flow": True, "rangefinder": True, "commands": _commands()}  # fmt: skip
    result = fly(scenario, tmp_path / "run")
    rig_log = pyulog.ULog(str(result.rig_log))
    autopilot_log = pyulog.ULog(str(result.autopilot_log))
    t, x, y, z = _series(rig_log, "vehicle_local_position_groundtruth", "x", "y", "z")
    start = np.array([x[np.searchsorted(t, 2.0)], y[np.searchsorted(t, 2.0)]])
    hold = (t >= HOLD_S[0]) & (t < HOLD_S[1])
    hold_error = np.abs(np.column_stack([x[hold], y[hold]]) - start).max(axis=0)
    assert hold_error.max() < HOLD_BOUND_M, hold_error
    assert np.abs(-z[hold] - HOVER_M).max() < 0.4
    errors = _corner_errors(rig_log, autopilot_log, start, CORNER_START_S, CORNER_S)
    assert max(errors) < CORNER_BOUND_M, errors
    assert -z[-1] < 0.05
    messages = [m.message for m in autopilot_log.logged_messages]
    assert "Landing detected" in messages
    assert any(text.startswith("Disarmed") for text in messages)
    assert not any("Failsafe" in text for text in messages), messages


def test_the_flow_chip_blind_in_a_hover_ends_in_the_descend_failsafe(tmp_path):
    """The chip sees nothing from 12 s (SQUAL 0: PX4's driver drops its readings): no flow is
    fused, EKF2_NOAID_TOUT (5 s) later the local position is invalid and, as PX4 falls back
    when neither Hold nor Land can run, it descends level, says why, and lands."""
    blind = {"kind": "flow_chip", "mode": "zero_quality", "start_s": 12.0}
    scenario = {"name": "flow_blind", "vehicle": "f450_high_precision", "duration_s": 30.0,
                "seed": 3, "sensor_layer": "tlm", "gps": False, "optical_flow": True,
                "rangefinder": True, "commands": _commands()[:2], "faults": [blind]}  # fmt: skip
    result = fly(scenario, tmp_path / "run")
    autopilot_log = pyulog.ULog(str(result.autopilot_log))
    messages = [(m.timestamp / 1e6, m.message) for m in autopilot_log.logged_messages]
    failsafe = [(t, text) for t, text in messages if "Failsafe" in text]
    assert failsafe, messages
    assert failsafe[0][1] == "Failsafe: no position (optical flow lost), Descend"
    assert 17.0 <= failsafe[0][0] < 17.5  # the last fusion before 12 s, plus 5 s
    t, z = _series(pyulog.ULog(str(result.rig_log)), "vehicle_local_position_groundtruth", "z")
    assert -z[np.searchsorted(t, 16.9)] > 2.0  # held until then
    assert -z[-1] < 0.05  # down


#: The bundled flight's times (rig/scenarios/optical_flow_hold.toml): the throttle stick
#: centred at 15 s, the first offboard corner at 42 s, 7 s apart, the landing at 70 s.
STICK_HOLD_S = (17.0, 37.0)
STICK_CORNER_START_S = 42.0
STICK_CORNER_S = 7.0


def test_the_bundled_flow_flight_takes_off_and_hovers_on_the_pilots_sticks(tmp_path):
    """`optical_flow_hold` (sensor_layer "tlm") with the reference autopilot: Position mode
    from the sticks, armed, the throttle stick at 0.8 for 4 s takes it off (PX4's take-off
    ramp), centred it holds hands-off within ±0.3 m for 20 s, then flies the offboard square
    (each corner within 0.5 m) and lands and disarms, with no failsafe. Measured: the
    hover at 2.70 m, within 0.07 m (x), 0.04 m (y) and 0.16 m of height; the corners within
    0.11-0.18 m."""
    flight = dataclasses.replace(load_scenario("optical_flow_hold"), sensor_layer="tlm")
    result = fly(flight, tmp_path / "run")
    rig_log = pyulog.ULog(str(result.rig_log))
    autopilot_log = pyulog.ULog(str(result.autopilot_log))
    messages = [m.message for m in autopilot_log.logged_messages]
    t, x, y, z = _series(rig_log, "vehicle_local_position_groundtruth", "x", "y", "z")
    start = np.array([x[np.searchsorted(t, 10.0)], y[np.searchsorted(t, 10.0)]])
    hold = (t >= STICK_HOLD_S[0]) & (t < STICK_HOLD_S[1])
    assert -z[hold].min() > 1.5, messages  # it took off on the throttle stick
    held = np.column_stack([x[hold], y[hold], z[hold]])
    assert np.abs(held - held[0]).max() < HOLD_BOUND_M, np.abs(held - held[0]).max(axis=0)
    errors = _corner_errors(rig_log, autopilot_log, start, STICK_CORNER_START_S, STICK_CORNER_S)
    assert max(errors) < CORNER_BOUND_M, errors
    assert -z[-1] < 0.05
    assert "Landing detected" in messages
    assert any(text.startswith("Disarmed") for text in messages)
    assert not any("Failsafe" in text for text in messages), messages


def test_flow_lost_in_position_mode_falls_back_to_altitude_and_the_throttle_stick_lands(
    tmp_path,
):
    """Position mode from the sticks, the chip blind from 14 s: EKF2_NOAID_TOUT later the
    position is invalid and, the pilot being on the sticks, PX4 falls back to Altitude
    (height held on the barometer and the rangefinder); the throttle stick held down from
    24 s lands it, and the land detector disarms it. Measured: the fallback at 19.0 s, the
    height held at 2.62-2.69 m (it coasts on at the 0.5 m/s it picked up while dead
    reckoning: Altitude mode has no horizontal control), landed at 28.8 s, disarmed at
    30.8 s."""
    commands = [
        {"at_s": 2.0, "action": "sticks", "throttle": -1.0},
        {"at_s": 3.0, "action": "mode", "name": "Position"},
        {"at_s": 4.0, "action": "arm"},
        {"at_s": 5.0, "action": "sticks", "throttle": 0.8},
        {"at_s": 9.0, "action": "sticks", "throttle": 0.0},
        {"at_s": 24.0, "action": "sticks", "throttle": -1.0},
    ]
    blind = {"kind": "flow_chip", "mode": "zero_quality", "start_s": 14.0}
    scenario = {"name": "flow_sticks_blind", "vehicle": "f450_high_precision",
                "duration_s": 36.0, "seed": 3, "sensor_layer": "tlm", "gps": False,
                "optical_flow": True, "rangefinder": True, "commands": commands,
                "faults": [blind]}  # fmt: skip
    result = fly(scenario, tmp_path / "run")
    autopilot_log = pyulog.ULog(str(result.autopilot_log))
    messages = [(m.timestamp / 1e6, m.message) for m in autopilot_log.logged_messages]
    failsafe = [(t, text) for t, text in messages if "Failsafe" in text]
    assert [text for _, text in failsafe] == [
        "Failsafe: no position (optical flow lost), Altitude"
    ], messages
    assert 19.0 <= failsafe[0][0] < 19.5  # the last fusion before 14 s, plus 5 s
    t, z = _series(pyulog.ULog(str(result.rig_log)), "vehicle_local_position_groundtruth", "z")
    held = -z[(t >= 19.5) & (t < 24.0)]
    assert held.min() > 1.5
    assert np.ptp(held) < 2 * HOLD_BOUND_M
    assert -z[-1] < 0.05
    texts = [text for _, text in messages]
    assert "Landing detected" in texts
    assert "Disarmed: landed (COM_DISARM_LAND)" in texts
