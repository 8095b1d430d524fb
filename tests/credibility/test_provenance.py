"""credibility.provenance: the firmware a ULog header names and the replay.json of a rig run,
in the report's JSON and HTML."""

import json
from pathlib import Path

import numpy as np
import pandas as pd

from credibility.assess import assess
from credibility.plan import load_plan
from credibility.provenance import firmware_name, provenance_of
from credibility.report import render_html, to_dict

X500_LOG = (
    Path(__file__).resolve().parents[2] / "data/flight_logs/px4_x500v2_v6xrt_flight_2026-03-20.ulg"
)


def test_firmware_names_decode_ver_sw_release():
    """ver_sw_release packs major.minor.patch and the type byte (PX4 px4_version.h):
    0x011100C0 is v1.17.0 release candidate, 0x010E00FF v1.14.0 release, type 0 a dev build."""
    info = {"ver_sw_release": 0x011100C0, "ver_sw": "0b6e4687defb", "ver_hw": "PX4_FMU_V6XRT"}
    assert firmware_name(info) == "PX4 v1.17.0rc (git 0b6e4687) on PX4_FMU_V6XRT"
    assert firmware_name({"ver_sw_release": 0x010E00FF}).startswith("PX4 v1.14.0 (git ?)")
    assert firmware_name({"ver_sw_release": 0x010E0000}).startswith("PX4 v1.14.0dev")


def test_the_report_shows_each_logs_firmware_and_replay(tmp_path):
    """The real ULog's header gives its firmware; a sim log in a replay's run folder brings
    the run's replay.json: the flight it replays, autopilot, vehicle model, parameters
    (skipped ones by reason), wind."""
    run = tmp_path / "run"
    run.mkdir()
    t = np.arange(0.0, 30.0, 0.01)
    pd.DataFrame({"time_s": t + 400.0, "battery_status.voltage_v": 15.0 + 0 * t}).to_csv(
        run / "sim.csv", index=False
    )
    summary = {
        "log": str(X500_LOG),
        "autopilot": "px4",
        "log_firmware": "PX4 v1.17.0rc (git 0b6e4687) on PX4_FMU_V6XRT",
        "vehicle": "x500_v2",
        "parameters_applied": {"MC_ROLLRATE_P": 0.14, "MC_ROLL_P": 4.0},
        "parameters_skipped": [
            {"name": "CAL_ACC0_ID", "value": 1.0, "reason": "a calibration"},
            {"name": "BMM350_ODR", "value": 3.0, "reason": "not a parameter of this PX4 build"},
            {"name": "CAL_GYRO0_ID", "value": 2.0, "reason": "a calibration"},
        ],
        "parameters_set_by_the_rig": {"IMU_INTEG_RATE": 800},
        "wind": {"speed_mps": 4.2, "bound_mps": 1.9, "from_deg": 19.0, "method": "hover tilt"},
        "imu_hz": 800,
        "seed": 0,
    }
    (run / "replay.json").write_text(json.dumps(summary))
    plan = tmp_path / "plan.toml"
    plan.write_text(
        f"""
[plan]
name = "provenance"

[logs]
real = "{X500_LOG}"
sim = "run/sim.csv"

[[tests]]
name = "voltage"
kind = "performance"
parameter = "mean"
signal = "battery_status.voltage_v"
segment_s = [410.0, 420.0]
"""
    )
    assessment = assess(load_plan(plan))
    logs = {log["role"]: log["provenance"] for log in to_dict(assessment)["logs"]}
    assert logs["real"] == {
        "firmware": "PX4 v1.17.0rc (git 0b6e4687) on PX4_FMU_V6XRT",
        "replay": None,
    }
    replay = logs["sim"]["replay"]
    assert logs["sim"]["firmware"] is None  # a CSV has no header
    assert replay["vehicle_model"] == "x500_v2"
    assert replay["parameters_applied"] == 2
    assert replay["parameters_skipped"] == {
        "a calibration": ["CAL_ACC0_ID", "CAL_GYRO0_ID"],
        "not a parameter of this PX4 build": ["BMM350_ODR"],
    }
    assert replay["wind"]["speed_mps"] == 4.2
    html = render_html(assessment)
    assert "Firmware, parameters and models" in html
    assert "2 of the flight&#39;s applied, 3 skipped (a calibration: 2;" in html
    assert "on vehicle model x500_v2" in html
    assert "4.2 ± 1.9 m/s from 19°" in html
    assert provenance_of(run / "sim.csv", "csv").replay["seed"] == 0
