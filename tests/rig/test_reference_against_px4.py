"""The reference autopilot against PX4 on the same chips: ``make hil-sim``'s flight (take-off
to 5 m, hover, a 5 m step north, back, land) flown by both, each judged on the rig's truth
and its own estimate, and the reference held to PX4's figures with stated tolerances.

PX4 is ``$PX4_DIR``'s build (CI: v1.17); without one the test skips. Both fly the TLM twin
of the RTL chips (byte-identical, ``tests/fpga_hdl``), at the scenario's IMU 1 kHz, as fast
as they go.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import pyulog

from rig.autopilots.px4 import PX4_DIR_ENV, find_px4
from rig.lockstep.loop import RunOptions, run_scenario
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import load_scenario

pytestmark = pytest.mark.closed_loop

#: The scenario's step: goto 5 m north at 20 s, held until 35 s (rig/scenarios/hil_sim.toml).
STEP_M, STEP_S, HOLD_S = 5.0, 20.0, (25.0, 35.0)
TAKEOFF_M = 5.0


@dataclass(frozen=True)
class Flight:
    """What a pilot judges a demo flight by (m, s; from ``rig.ulg``'s truth and the
    autopilot's own ``vehicle_local_position`` with its offset on the ground removed)."""

    takeoff_peak_m: float
    step_overshoot: float  # fraction of the step
    hold_error_m: float  # mean truth minus the step's target over the hold
    hold_estimate_error_m: float  # largest |estimate - truth| north in the hold
    landing_detected_after_s: float  # "Landing detected" minus the truth's touchdown


def judge(run_dir: Path, autopilot_log: Path) -> Flight:
    rig, own = pyulog.ULog(str(run_dir / "rig.ulg")), pyulog.ULog(str(autopilot_log))
    truth = rig.get_dataset("vehicle_local_position_groundtruth").data
    estimate = own.get_dataset("vehicle_local_position").data
    t, est_t = truth["timestamp"] / 1e6, estimate["timestamp"] / 1e6
    # half a second on the ground, after the estimate's first half second: PX4's EKF2
    # starts to publish anywhere from 0.5 s to past 1 s of simulated time, as far as its
    # start-up script (in wall time) has got when the rig's frames start
    ground = (est_t > est_t[0] + 0.5) & (est_t < est_t[0] + 1.0)
    offset = np.mean(estimate["x"][ground] - np.interp(est_t[ground], t, truth["x"]))
    hold = (t > HOLD_S[0]) & (t < HOLD_S[1])
    estimate_x = np.interp(t[hold], est_t, estimate["x"]) - offset
    after_step = (t > STEP_S) & (t < HOLD_S[1])
    detected_s = max(m.timestamp / 1e6 for m in own.logged_messages
                     if "anding detected" in m.message)  # fmt: skip
    landed = (t > HOLD_S[1]) & (-truth["z"] < 0.02)
    return Flight(
        takeoff_peak_m=float(-truth["z"][t < STEP_S - 5.0].min()),
        step_overshoot=float(truth["x"][after_step].max() - STEP_M) / STEP_M,
        hold_error_m=float(truth["x"][hold].mean() - STEP_M),
        hold_estimate_error_m=float(np.abs(estimate_x - truth["x"][hold]).max()),
        landing_detected_after_s=detected_s - float(t[landed][0]),
    )


def fly(tmp_path, free_instance, autopilot: str, px4_dir: Path | None = None) -> Flight:
    options = RunOptions(
        autopilot=autopilot, px4_dir=px4_dir, instance=free_instance(), sensor_layer="tlm",
        out_dir=tmp_path / autopilot, timeouts=LinkTimeouts(connect_s=60, answer_s=30),
    )  # fmt: skip
    result = run_scenario(load_scenario("hil_sim"), options)
    assert result.autopilot_log is not None
    return judge(result.run_dir, result.autopilot_log)


def test_the_reference_autopilot_flies_the_demo_as_px4_does(tmp_path, free_instance):
    """Step overshoot within 5 percentage points of PX4's, the hold's error and the
    estimate's error within 0.1 m of PX4's, the take-off's overshoot at most 5 %, and the
    landing detected no more than 2 s later after touchdown than PX4 detects it."""
    build = find_px4()
    if build is None:
        pytest.skip(
            f"no PX4 SITL build: set {PX4_DIR_ENV} (CI points it at ../shared/px4_sitl_v1_17)"
        )
    px4 = fly(tmp_path, free_instance, "px4", build.root)
    reference = fly(tmp_path, free_instance, "reference")
    assert abs(reference.step_overshoot - px4.step_overshoot) < 0.05, (reference, px4)
    assert abs(reference.hold_error_m - px4.hold_error_m) < 0.1, (reference, px4)
    assert reference.hold_estimate_error_m < px4.hold_estimate_error_m + 0.1, (reference, px4)
    assert reference.takeoff_peak_m <= TAKEOFF_M * 1.05, reference
    assert abs(reference.landing_detected_after_s - px4.landing_detected_after_s) < 2.0, (
        reference, px4)  # fmt: skip
