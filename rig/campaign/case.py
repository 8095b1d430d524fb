"""One campaign case in its own process: ``python -m rig.campaign.case CASE_DIR``.

Reads ``case.json`` and ``scenario.toml`` (written by :func:`rig.campaign.executor.run_case`),
flies it on a free SITL instance, computes the metrics from the run's logs and writes
``outcome.json`` (``{"error": ..., "metrics": {...}, "notes": [...]}``) atomically. A
process of its own per case keeps ports, sockets, the autopilot and any crash inside the
case; SIGINT (the campaign's timeout or Ctrl-C) ends the run cleanly with its logs
readable.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pyulog

from credibility import CredibilityError, assess, load_plan
from rig.errors import RigError
from rig.lockstep.loop import RunOptions, run_scenario
from rig.mavlink.px4_api import free_instance
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import load_scenario

#: Altitude (m) under which a downward speed counts as the ground impact speed; at the
#: 250 Hz truth rate a 10 m/s fall moves 4 cm per sample, so the last sample is caught.
IMPACT_ALTITUDE_M = 0.2


def main(argv: list[str] | None = None) -> int:
    run_dir = Path((sys.argv[1:] if argv is None else argv)[0])
    case = json.loads((run_dir / "case.json").read_text())
    try:
        try:
            instance = free_instance(case["first_instance"], case["instances"], case["index"])
        except OSError as error:
            raise RigError(str(error)) from None
        options = RunOptions(
            instance=instance,
            out_dir=run_dir,
            sensor_layer=case["sensor_layer"],
            timeouts=LinkTimeouts(connect_s=60.0, answer_s=case["answer_timeout_s"]),
            autopilot_params=tuple(case["autopilot_params"]),
            force=True,  # the campaign reruns a case that did not finish in its own folder
        )
        result = run_scenario(load_scenario(run_dir / "scenario.toml"), options)
        metrics = case_metrics(
            result.rig_log, result.autopilot_log, case["onset_s"], **case["crash"]
        )
        notes = []
        if case["credibility"] is not None:
            logs = {"rig": result.rig_log, "autopilot": result.autopilot_log}
            scoring = case["credibility"]  # its plan_sha256 is kept once by the campaign
            scores, note = credibility_metrics(
                logs, scoring["plan_path"], scoring["role"], scoring["log"]
            )
            metrics.update(scores)
            notes += [note] if note else []
        outcome: dict[str, Any] = {"error": None, "metrics": metrics, "notes": notes}
    except RigError as error:
        outcome = {"error": str(error), "metrics": {}}
    except KeyboardInterrupt:
        return 130  # stopped by the campaign: no outcome, the campaign knows why
    written = run_dir / "outcome.json.part"
    written.write_text(json.dumps(outcome, sort_keys=True))
    os.replace(written, run_dir / "outcome.json")  # all or nothing
    return 0


def case_metrics(
    rig_log: Path,
    autopilot_log: Path | None,
    onset_s: float | None,
    tilt_deg: float,
    impact_speed_mps: float,
) -> dict[str, Any]:
    """The case's metrics from the ground truth in ``rig.ulg`` (and the autopilot's
    messages): over the window from ``onset_s`` (the whole run without one)."""
    log = pyulog.ULog(
        str(rig_log), ["vehicle_attitude_groundtruth", "vehicle_local_position_groundtruth"]
    )
    attitude = log.get_dataset("vehicle_attitude_groundtruth").data
    position = log.get_dataset("vehicle_local_position_groundtruth").data
    start_s = onset_s or 0.0
    tilts = tilt_from_level_deg(*(attitude[f"q[{i}]"] for i in range(4)))
    in_window = attitude["timestamp"] / 1e6 >= start_s
    time_s, altitude_m = position["timestamp"] / 1e6, -position["z"].astype(float)
    after = time_s >= start_s
    altitude_at_onset_m = float(np.interp(start_s, time_s, altitude_m))
    near_ground = altitude_m < IMPACT_ALTITUDE_M
    impact = float(max(0.0, *position["vz"][near_ground])) if near_ground.any() else 0.0
    max_tilt = float(tilts[in_window].max()) if in_window.any() else 0.0
    return {
        "max_tilt_deg": round(max_tilt, 6),
        "altitude_loss_m": round(
            max(0.0, altitude_at_onset_m - float(altitude_m[after].min())) if after.any() else 0.0,
            6,
        ),
        "time_to_failsafe_s": _time_to_failsafe(autopilot_log, start_s),
        "impact_speed_mps": round(impact, 6),
        "crashed": bool(tilts.max() > tilt_deg or impact > impact_speed_mps),
    }


def credibility_metrics(
    logs: dict[str, Path | None], plan_path: str, role: str, log: str
) -> tuple[dict[str, float | None], str | None]:
    """``eta_all`` and ``eta_min`` of the plan with the case's ``log`` in ``role``, and why
    they are missing (None if they are not): a plan that cannot score this run (a segment
    past its end, a topic it lacks) is the case's finding, not a crash of the case."""
    case_log = logs[log]
    try:
        if case_log is None:
            raise CredibilityError(f"the run wrote no {log}.ulg")
        assessment = assess(load_plan(Path(plan_path), {role: case_log}))
    except CredibilityError as error:
        missing = dict.fromkeys(("eta_all", "eta_min"))
        return missing, f"credibility not assessed: {error}"
    # assess is strict: a test it cannot score raises above, so every test is scored and
    # the indices exist
    assert assessment.eta_all is not None
    assert assessment.eta_min is not None
    return {
        "eta_all": round(float(assessment.eta_all), 6),
        "eta_min": round(float(assessment.eta_min), 6),
    }, None


def tilt_from_level_deg(w: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Angle between the body z axis and the vertical: R[2,2] = 1 − 2(x² + y²) of the
    body-to-NED rotation of a unit quaternion (w, x, y, z)."""
    del w, z  # the tilt does not depend on them
    return np.degrees(np.arccos(np.clip(1.0 - 2.0 * (x * x + y * y), -1.0, 1.0)))


def _time_to_failsafe(autopilot_log: Path | None, start_s: float) -> float | None:
    """Seconds from ``start_s`` to the autopilot's first "Failsafe" message (PX4 words its
    failsafe notices so), None without one."""
    if autopilot_log is None:
        return None
    messages = pyulog.ULog(str(autopilot_log), []).logged_messages
    times = [
        m.timestamp / 1e6
        for m in messages
        if "failsafe" in m.message.lower() and m.timestamp / 1e6 >= start_s
    ]
    return round(min(times) - start_s, 6) if times else None


if __name__ == "__main__":
    sys.exit(main())
