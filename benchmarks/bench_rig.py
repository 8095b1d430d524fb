"""Closed-loop speed: real-time factor and frames per second of the rig, TLM and RTL sensors.

Targets from the issue (figures only, no pass/fail): ``rtl`` ≥ 1.0× real time and
``tlm`` ≥ 20× on 2 cores. Each case flies a short scenario end to end: model, sensor
physics, chips and PX4's drivers, HIL encoding, lockstep over TCP, PWM capture, rig.ulg.

Two autopilots: the reference autopilot (the product's loop), and the PX4-side test double
of ``tests/rig`` (answers each frame at a fixed throttle, doing almost no work), which
shows the rig's own cost. "waiting" is the share of wall time the rig spent blocked on
the autopilot's answers.
"""

from __future__ import annotations

import importlib.util
import sys
import tempfile
from pathlib import Path

from rig.errors import RigError
from rig.link import LinkTimeouts
from rig.loop import RunOptions, run_scenario
from rig.px4_sim_api import Ports
from rig.scenario import scenario_from_dict

REPO = Path(__file__).resolve().parent.parent
DOUBLE = REPO / "tests" / "rig" / "autopilot_double.py"
INSTANCE = 90  # away from the instances tests and users pick first
SIMULATED_S = {"tlm": 6.0, "rtl": 3.0}


def _scenario(sensor_layer: str, imu_hz: int) -> object:
    return scenario_from_dict(
        {
            "name": "bench_hover",
            "vehicle": "f450_high_precision",
            "duration_s": SIMULATED_S[sensor_layer],
            "seed": 1,
            "sensor_layer": sensor_layer,
            "rates": {"imu_hz": imu_hz},
            "commands": [
                {"at_s": 0.5, "action": "arm"},
                {"at_s": 0.6, "action": "takeoff", "altitude_m": 2.0},
            ],
        }
    )


def _case(sensor_layer: str, imu_hz: int, autopilot: str) -> None:
    scenario = _scenario(sensor_layer, imu_hz)
    argv = None
    if autopilot == "double":
        port = Ports(INSTANCE).simulator_tcp
        argv = (sys.executable, str(DOUBLE), "--port", str(port), "--behaviour", "px4",
                "--throttle", "0.55", "--arm-after", "500")  # fmt: skip
        scenario = scenario_from_dict({**_as_document(scenario), "commands": []})
    with tempfile.TemporaryDirectory() as folder:
        options = RunOptions(
            instance=INSTANCE,
            out_dir=Path(folder),
            timeouts=LinkTimeouts(connect_s=600, answer_s=30),
            autopilot_argv=argv,
        )
        try:
            result = run_scenario(scenario, options)
        except RigError as error:
            print(f"{sensor_layer:>3}  IMU {imu_hz:>4} Hz  {autopilot:<9}  failed: {error}")
            return
    waiting = result.link.lockstep_wait_s / result.wall_s
    print(
        f"{sensor_layer:>3}  IMU {imu_hz:>4} Hz  {autopilot:<9}"
        f"  RTF {result.real_time_factor:6.2f}x"
        f"  {result.frames / result.wall_s:8.0f} frames/s  waiting {waiting:4.0%}"
        f"  ({result.simulated_s:.0f} s simulated in {result.wall_s:.1f} s)",
        flush=True,
    )


def _as_document(scenario: object) -> dict:
    return {
        "name": scenario.name,
        "vehicle": scenario.vehicle,
        "duration_s": scenario.duration_s,
        "seed": scenario.seed,
        "sensor_layer": scenario.sensor_layer,
        "rates": {"imu_hz": scenario.rates.imu_hz},
    }


def main() -> None:
    autopilots = ["double"]
    if importlib.util.find_spec("rig.autopilot.__main__") is not None:
        autopilots.insert(0, "reference")
    else:
        print("(reference autopilot not installed: `python -m rig.autopilot` is missing)")
    for sensor_layer in ("tlm", "rtl"):
        for imu_hz in (1000, 250):
            for autopilot in autopilots:
                _case(sensor_layer, imu_hz, autopilot)
    print("targets: rtl >= 1.0x, tlm >= 20x real time (2 cores)")


if __name__ == "__main__":
    main()
