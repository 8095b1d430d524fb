"""Golden run: the speed work on the TLM loop changed no number the rig produces.

The same short closed loop (test-double autopilot, every fault kind that touches the rig's
own code) is flown twice, one run after the other on the same ports: once with the rig's
loop, link, encoders, chip models, TLM buses, PWM, faults and logger as they were at
:data:`BASELINE_COMMIT` (read from git at run time), once with the current ones. Every
logged topic, every field and every logged message must be identical. Move
:data:`BASELINE_COMMIT` only when a change of the rig's output is intended.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import pyulog

pytestmark = pytest.mark.closed_loop

REPO = Path(__file__).resolve().parents[2]
DOUBLE = Path(__file__).with_name("autopilot_double.py")
#: The rig before the TLM speed work (commit "rig.sensor_layer: SensorLayer protocol").
BASELINE_COMMIT = "69e860126b97db6f6c3ffb50e81e0e77f3029c88"
#: The modules the speed work touched, replaced by their baseline versions in the "before" run.
BASELINE_MODULES = (
    "rig/loop.py", "rig/link.py", "rig/sim_messages.py", "rig/sensor_layer.py", "rig/pwm.py",
    "rig/rig_log.py", "rig/faults.py", "fpga_hdl/buses.py", "fpga_hdl/mpu6000/model.py",
    "fpga_hdl/ms5611/model.py", "fpga_hdl/ist8310/model.py",
)  # fmt: skip
SCENARIO = {
    "name": "golden",
    "vehicle": "f450_high_precision",
    "duration_s": 1.2,
    "seed": 11,
    "faults": [
        {"kind": "sensor_stuck", "sensor": "gyro", "start_s": 0.30, "end_s": 0.35},
        {"kind": "sensor_bias", "sensor": "baro", "bias": 300.0, "start_s": 0.4},
        {"kind": "noise_burst", "sensor": "accel", "std": 0.5, "start_s": 0.5, "end_s": 0.6},
        {"kind": "bus_bit_flip", "chip": "mpu6000", "mask": 0x81, "start_s": 0.62,
         "end_s": 0.66},
        {"kind": "bus_bit_flip", "chip": "ms5611", "mask": 0x04, "start_s": 0.7, "end_s": 0.8},
        {"kind": "chip_mute", "chip": "ist8310", "start_s": 0.85, "end_s": 0.95},
        {"kind": "gps_loss", "start_s": 0.9, "end_s": 1.0},
        {"kind": "pwm_dropout", "channel": 2, "start_s": 1.0, "end_s": 1.1},
        {"kind": "motor_degradation", "motor": 1, "efficiency": 0.7, "start_s": 0.2},
    ],
}  # fmt: skip

#: Flies SCENARIO; argv: instance, out_dir, then "baseline" to load the baseline modules.
RUNNER = """
import importlib.abc, importlib.util, json, subprocess, sys
from pathlib import Path

instance, out_dir, which, repo, double, commit, modules, document = sys.argv[1:9]
if which == "baseline":
    sources = {
        path[:-3].replace("/", "."): subprocess.run(
            ["git", "-C", repo, "show", f"{commit}:{path}"], check=True, capture_output=True,
            text=True).stdout
        for path in json.loads(modules)
    }

    class Baseline(importlib.abc.MetaPathFinder, importlib.abc.Loader):
        def find_spec(self, name, path=None, target=None):
            if name in sources:
                return importlib.util.spec_from_loader(name, self, origin=f"{commit}:{name}")
            return None

        def create_module(self, spec):
            return None

        def exec_module(self, module):
            name = module.__name__
            exec(compile(sources[name], f"<{commit[:7]}>/{name}", "exec"), module.__dict__)

    sys.meta_path.insert(0, Baseline())

from rig.link import LinkTimeouts
from rig.loop import RunOptions, run_scenario
from rig.px4_sim_api import Ports
from rig.scenario import scenario_from_dict

port = Ports(int(instance)).simulator_tcp
argv = (sys.executable, double, "--port", str(port), "--behaviour", "px4", "--throttle",
        "0.62", "--arm-after", "150")
options = RunOptions(instance=int(instance), out_dir=Path(out_dir), autopilot_argv=argv,
                     timeouts=LinkTimeouts(connect_s=30, answer_s=10))
run_scenario(scenario_from_dict(json.loads(document)), options)
"""


def _fly(which: str, instance: int, out_dir: Path) -> pyulog.ULog:
    args = (str(instance), str(out_dir), which, str(REPO), str(DOUBLE), BASELINE_COMMIT,
            json.dumps(BASELINE_MODULES), json.dumps(SCENARIO))  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    subprocess.run([sys.executable, "-c", RUNNER, *args], check=True, cwd=REPO, env=env)
    return pyulog.ULog(str(out_dir / "rig.ulg"))


def _datasets(log: pyulog.ULog) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    return {(d.name, d.multi_id): d.data for d in log.data_list}


def test_the_rig_log_is_the_baseline_rig_log(tmp_path, free_instance):
    known = subprocess.run(["git", "-C", str(REPO), "cat-file", "-e", BASELINE_COMMIT],
                           capture_output=True)  # fmt: skip
    if known.returncode != 0:
        pytest.skip(f"baseline commit {BASELINE_COMMIT[:7]} is not in this clone's history")
    instance = free_instance()
    before = _fly("baseline", instance, tmp_path / "baseline")
    after = _fly("current", instance, tmp_path / "current")

    assert before.msg_info_dict == after.msg_info_dict
    assert before.initial_parameters == after.initial_parameters
    events = [(m.timestamp, m.log_level, m.message) for m in before.logged_messages]
    assert events == [(m.timestamp, m.log_level, m.message) for m in after.logged_messages]
    assert any(text.startswith("bus error: ist8310") for _, _, text in events)  # faults ran
    before_data, after_data = _datasets(before), _datasets(after)
    assert before_data.keys() == after_data.keys()
    for key, expected in before_data.items():
        actual = after_data[key]
        assert expected.keys() == actual.keys(), key
        if key[0] == "actuator_motors":
            # The autopilot's answers are logged from the frame lockstep began, which
            # depends on when its first answer arrived: compare from the later start.
            start = max(expected["timestamp"][0], actual["timestamp"][0])
            expected = {k: v[expected["timestamp"] >= start] for k, v in expected.items()}
            actual = {k: v[actual["timestamp"] >= start] for k, v in actual.items()}
        for field in expected:
            np.testing.assert_array_equal(actual[field], expected[field], err_msg=f"{key} {field}")
