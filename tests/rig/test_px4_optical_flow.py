"""PX4 flies without GPS on the PMW3901 optical-flow chip and the LIDAR-Lite, through the RTL
chips at IMU 1 kHz, on every release: a pilot takes off in Position mode and lets go of the
sticks (PX4 holds its position on flow alone), then a companion computer flies a square in
offboard position set-points, and PX4 lands. With the chip's quality at 0 PX4 loses its
position and falls back to Altitude mode, as its documentation says."""

import dataclasses

import numpy as np
import pytest
import pyulog

from rig.lockstep.loop import RunOptions, run_scenario
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import FlowChipFault, Goto, load_scenario
from tests.rig.px4_flights import inside, topic

pytestmark = [pytest.mark.closed_loop, pytest.mark.cosim]

#: The bundled flight: the pilot's Position-mode take-off by 15 s, hands off, the offboard
#: square's first corner at 42 s (a leg every 7 s), land at 70 s. The RTL chips at 1 kHz.
FLIGHT = dataclasses.replace(load_scenario("optical_flow_hold"), sensor_layer="rtl")
#: Hands off: 20 s of hover, judged on the truth.
HOVER_S = (20.0, 40.0)
SQUARE = [c for c in FLIGHT.commands if isinstance(c, Goto)]
LEG_S = SQUARE[1].at_s - SQUARE[0].at_s
#: How close PX4 holds and flies: the issue's figures (measured on v1.14 and v1.17 through
#: the RTL chips: the hover within 0.1 m, the corners within 0.2 m).
HOVER_TOLERANCE_M, CORNER_TOLERANCE_M = 0.3, 0.5


def _fly(tmp_path, free_instance, px4_dir, scenario):
    options = RunOptions(
        autopilot="px4", px4_dir=px4_dir, instance=free_instance(),
        out_dir=tmp_path / scenario.name, timeouts=LinkTimeouts(connect_s=60, answer_s=30),
    )  # fmt: skip
    result = run_scenario(scenario, options)
    return pyulog.ULog(str(result.rig_log)), pyulog.ULog(str(result.autopilot_log))


def _ground_offset(rig_log, px4_log) -> dict[str, float]:
    """PX4's local frame against the truth's, on the ground before arming (EKF2's origin is
    where it started, which the truth's is too, less the estimate's error then)."""
    truth_t, truth = topic(rig_log, "vehicle_local_position_groundtruth")
    est_t, est = topic(px4_log, "vehicle_local_position")
    ground = inside(est_t, (7.0, 9.5))
    return {axis: float(np.mean(est[axis][ground] - np.interp(est_t[ground], truth_t, truth[axis])))
            for axis in "xy"}  # fmt: skip


def test_px4_holds_and_flies_a_square_on_optical_flow_without_gps(tmp_path, free_instance, any_px4):
    """No GPS reaches PX4; EKF2 fuses the chip's flow; hands off in Position mode the truth
    stays within HOVER_TOLERANCE_M of where it hovers for 20 s; the second half of each leg
    of the 2 m square passes within CORNER_TOLERANCE_M of its corner; it lands and disarms."""
    rig_log, px4_log = _fly(tmp_path, free_instance, any_px4.root, FLIGHT)
    params = px4_log.initial_parameters
    assert (params["EKF2_GPS_CTRL"], params["EKF2_OF_CTRL"], params["SYS_HAS_GPS"]) == (0, 1, 0)
    assert "vehicle_gps_position" not in {d.name for d in px4_log.data_list}
    flags_t, flags = topic(px4_log, "estimator_status_flags")
    assert flags["cs_opt_flow"][inside(flags_t, HOVER_S)].all(), "EKF2 stopped fusing flow"
    status_t, status = topic(px4_log, "vehicle_status")
    hovering = inside(status_t, HOVER_S)
    assert set(status["nav_state"][hovering]) == {2}, "not in Position mode through the hover"

    truth_t, truth = topic(rig_log, "vehicle_local_position_groundtruth")
    window = inside(truth_t, HOVER_S)
    north, east = truth["x"][window], truth["y"][window]
    wander = np.hypot(north - north.mean(), east - east.mean())
    assert wander.max() < HOVER_TOLERANCE_M, f"hover wandered {wander.max():.2f} m"
    assert -truth["z"][window].mean() > 1.5, "the pilot's climb did not reach hover height"

    offset = _ground_offset(rig_log, px4_log)
    for k, goto in enumerate(SQUARE):
        corner = goto.position_ned_m[:2]
        leg = inside(truth_t, (goto.at_s + LEG_S / 2, goto.at_s + LEG_S))
        reached = np.column_stack([truth["x"][leg] + offset["x"], truth["y"][leg] + offset["y"]])
        error = np.linalg.norm(reached - corner, axis=1).min()
        assert error < CORNER_TOLERANCE_M, f"corner {k} {corner} missed by {error:.2f} m"
    _, armed = topic(px4_log, "actuator_armed")
    assert not armed["armed"][-1], "PX4 did not disarm after landing"
    assert abs(truth["z"][-1]) < 0.05


def test_px4_falls_back_to_altitude_mode_when_the_flow_chip_sees_nothing(
    tmp_path, free_instance, px4_dir
):
    """SQUAL 0 from the chip at 25 s: PX4's driver drops every reading, EKF2 loses its only
    horizontal aid and, after its no-aid timeout, its position; PX4 leaves Position mode for
    Altitude mode (its position-loss failsafe in a manual mode) and keeps the height."""
    blind = dataclasses.replace(
        FLIGHT, name="flow_blind", duration_s=40.0,
        commands=tuple(c for c in FLIGHT.commands if c.at_s < 40.0),
        faults=(FlowChipFault(mode="zero_quality", start_s=25.0),),
    )  # fmt: skip
    rig_log, px4_log = _fly(tmp_path, free_instance, px4_dir, blind)
    flow_t, flow = topic(px4_log, "sensor_optical_flow")
    assert (flow["quality"][flow_t > 25.5] == 0).all()
    status_t, status = topic(px4_log, "vehicle_status")
    assert status["nav_state"][inside(status_t, (20.0, 25.0))].tolist().count(2) > 0
    after = status["nav_state"][status_t > 35.0]
    assert set(after) == {1}, f"PX4 flies in modes {sorted(set(after))} after the flow was lost"
    truth_t, truth = topic(rig_log, "vehicle_local_position_groundtruth")
    assert (-truth["z"][truth_t > 30.0] > 1.0).all(), "PX4 did not keep its height"
