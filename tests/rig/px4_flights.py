"""What the PX4 flight tests share: the builds to fly, a flight, and how it is judged.

PX4 is ``$PX4_DIR``'s build (CI: the newest release it has); the short subset of
``test_px4_sitl.py`` also flies each build in ``$PX4_OLDER_DIRS`` (CI: v1.14). Numbers come
from the rig's ground truth (``rig.ulg``) and PX4's own ULog (``px4.ulg``).
"""

import os
from pathlib import Path

import numpy as np
import pytest

from rig.autopilots.px4 import PX4_DIR_ENV
from rig.lockstep.loop import RunOptions, run_scenario
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import scenario_from_dict

#: Older PX4 builds (``os.pathsep``-separated) that the short subset flies too.
PX4_OLDER_DIRS_ENV = "PX4_OLDER_DIRS"
NO_PX4 = f"no PX4 SITL build: set {PX4_DIR_ENV} (CI points it at ../shared/px4_sitl_v1_17)"


def every_build() -> list:
    """$PX4_DIR's build, then each of $PX4_OLDER_DIRS'; a skip mark without any."""
    folders = [os.environ.get(PX4_DIR_ENV, ""),
               *os.environ.get(PX4_OLDER_DIRS_ENV, "").split(os.pathsep)]  # fmt: skip
    return [pytest.param(Path(f), id=Path(f).name) for f in folders if f] or [
        pytest.param(None, id="no-px4")
    ]


def fly_px4(tmp_path, free_instance, px4_dir, name, duration_s, commands=(), params=(),
            **scenario):  # fmt: skip
    """Fly a scenario of ``scenario``'s keys with PX4, ``params`` its ``--param`` texts."""
    document = {"name": name, "vehicle": "f450_high_precision", "duration_s": duration_s,
                "seed": scenario.pop("seed", 1), "sensor_layer": "tlm",
                "commands": list(commands), **scenario}  # fmt: skip
    options = RunOptions(
        autopilot="px4", px4_dir=px4_dir, instance=free_instance(), out_dir=tmp_path / name,
        timeouts=LinkTimeouts(connect_s=60, answer_s=30), autopilot_params=tuple(params),
    )  # fmt: skip
    return run_scenario(scenario_from_dict(document), options)


def topic(log, name):
    data = log.get_dataset(name).data
    return data["timestamp"] / 1e6, data


def inside(t, window_s):
    return (t > window_s[0]) & (t < window_s[1])


def ready_s(px4_log) -> float:
    """When PX4's pre-flight checks first passed ("Ready for takeoff!")."""
    t, status = topic(px4_log, "vehicle_status")
    passed = status["pre_flight_checks_pass"] > 0
    assert passed.any(), "PX4 never passed its pre-flight checks"
    return float(t[np.argmax(passed)])


class Hover:
    """PX4's estimate and setpoint against the rig's truth over a hover window.

    PX4's local frame starts where EKF2 aligned with GPS, so its origin differs from the
    truth's by the receiver's absolute error at that moment: that offset, taken on the
    ground before arming, is removed. What remains is the error PX4 flies with.
    """

    def __init__(self, rig_log, px4_log, ground_s, window_s):
        truth_t, truth = topic(rig_log, "vehicle_local_position_groundtruth")
        est_t, est = topic(px4_log, "vehicle_local_position")
        sp_t, sp = topic(px4_log, "vehicle_local_position_setpoint")
        on_ground, hovering = inside(est_t, ground_s), inside(truth_t, window_s)
        t = truth_t[hovering]
        self.estimate_error_m, offset = {}, {}
        for axis in "xyz":
            truth_at_estimate = np.interp(est_t, truth_t, truth[axis])
            offset[axis] = np.mean(est[axis][on_ground] - truth_at_estimate[on_ground])
            estimate = np.interp(t, est_t, est[axis]) - offset[axis]
            self.estimate_error_m[axis] = estimate - truth[axis][hovering]
        setpoint_z = np.interp(t, sp_t, sp["z"]) - offset["z"]
        self.truth_minus_setpoint_m = truth["z"][hovering] - setpoint_z
        self.estimate_minus_setpoint_m = np.interp(t, est_t, est["z"]) - offset["z"] - setpoint_z
        self.height_m = float(-truth["z"][hovering].mean())
        after_ground = est_t > ground_s[1]
        self.resets = {name: len(np.unique(est[name][after_ground])) - 1
                       for name in ("xy_reset_counter", "z_reset_counter")}  # fmt: skip


def takeoff_hover_land(arm_s, land_s, altitude_m=2.5):
    return [{"at_s": arm_s, "action": "arm"},
            {"at_s": arm_s + 0.5, "action": "takeoff", "altitude_m": altitude_m},
            {"at_s": land_s, "action": "land"}]  # fmt: skip
