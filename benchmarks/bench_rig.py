"""Closed-loop speed: real-time factor, per-frame budget and memory of the rig.

Targets from the issue (figures only, no pass/fail): ``rtl`` ≥ 1.0× real time and
``tlm`` ≥ 20× on 2 cores. Each case flies a short scenario end to end: model, sensor
physics, chips and PX4's drivers, HIL encoding, lockstep over TCP, PWM capture, rig.ulg.

Two autopilots: the reference autopilot (the product's loop), and the PX4-side test double
of ``tests/rig`` (answers each frame at a fixed throttle, doing almost no work), which
shows the rig's own cost. The budget splits each frame's wall time (µs) into the parts of
:class:`rig.lockstep.loop.FrameBudget`. The lockstep is sequential, so the autopilot's compute
adds to the frame: it shows as ``wait`` (blocked on the answer beyond the model step,
sensor sampling and logging the rig overlaps with it) and inside ``send`` (the send wakes
the autopilot, which often runs on the sender's core before the send returns).

The budget before the TLM speed work is printed first (:data:`BEFORE`), for comparison.

20× is 50 µs per frame at 1 kHz and 200 µs at 250 Hz, rig and autopilot together. The
model step and sensor physics (quad_model, numpy per sample) alone take 110-150 µs, the
loopback round trip with its two process wake-ups 20-80 µs, and the rest of the chip path
is fpga_hdl's numpy decode and tick-exact PWM model. Reaching it would need the whole
frame (model, sensor physics, chip words and register models, driver decode) compiled as
one kernel, logging batched into blocks, the autopilot compiled likewise, and an idle
second core for the autopilot; see the README's speed section.

``python -m benchmarks.bench_rig --peak-rss`` flies one 60 s TLM run with the reference
autopilot and prints the peak resident memory of the rig (early in the run and at its
end: a flat figure means no per-frame growth) and of the autopilot process.
"""

from __future__ import annotations

import importlib.util
import resource
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

from rig.errors import RigError
from rig.lockstep.loop import FrameBudget, Progress, RunOptions, RunResult, run_scenario
from rig.mavlink.px4_api import Ports
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import Scenario, scenario_from_dict

REPO = Path(__file__).resolve().parent.parent
DOUBLE = REPO / "tests" / "rig" / "autopilot_double.py"
INSTANCE = 90  # away from the instances tests and users pick first
SIMULATED_S = {"tlm": 6.0, "rtl": 3.0}
PEAK_RSS_SIMULATED_S = 60.0
#: TLM budget at commit 5ba0e5d, before the speed work: µs per frame in BUDGET_COLUMNS
#: order, then the RTF. Medians of 3 runs alternating with the speed work's code on the
#: shared 2-core machine (load average 2-3), so the two sets of figures compare.
BEFORE = {
    "tlm IMU 1000 Hz double": ((21, 92, 154, 56, 80, 12, 34, 7), 2.2),
    "tlm IMU 1000 Hz reference": ((23, 98, 165, 66, 211, 33, 39, 11), 1.5),
    "tlm IMU  250 Hz double": ((40, 102, 206, 66, 87, 9, 67, 10), 6.8),
    "tlm IMU  250 Hz reference": ((41, 110, 222, 78, 280, 90, 75, 16), 4.4),
}
#: Columns of the budget table: (heading, FrameBudget field).
BUDGET_COLUMNS = (
    ("model", "model_us"), ("sensors", "sensor_physics_us"), ("chips", "chips_us"),
    ("mavlink", "mavlink_us"), ("send", "socket_send_us"), ("wait", "autopilot_wait_us"),
    ("log", "logging_us"), ("other", "other_us"),
)  # fmt: skip


def _scenario(sensor_layer: str, imu_hz: int, autopilot: str, duration_s: float) -> Scenario:
    commands = [
        {"at_s": 0.5, "action": "arm"},
        {"at_s": 0.6, "action": "takeoff", "altitude_m": 2.0},
    ]
    return scenario_from_dict(
        {
            "name": "bench_hover",
            "vehicle": "f450_high_precision",
            "duration_s": duration_s,
            "seed": 1,
            "sensor_layer": sensor_layer,
            "rates": {"imu_hz": imu_hz},
            "commands": commands if autopilot == "reference" else [],
        }
    )


def _fly(
    sensor_layer: str,
    imu_hz: int,
    autopilot: str,
    duration_s: float,
    progress: Callable[[Progress], None] | None = None,
) -> RunResult:
    argv = None
    if autopilot == "double":
        port = Ports(INSTANCE).simulator_tcp
        argv = (sys.executable, str(DOUBLE), "--port", str(port), "--behaviour", "px4",
                "--throttle", "0.55", "--arm-after", "500")  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        options = RunOptions(
            instance=INSTANCE,
            out_dir=Path(folder),
            timeouts=LinkTimeouts(connect_s=600, answer_s=30),
            autopilot_argv=argv,
        )
        return run_scenario(
            _scenario(sensor_layer, imu_hz, autopilot, duration_s), options, progress
        )


def _budget_heading() -> str:
    parts = "".join(f"{heading:>8}" for heading, _ in BUDGET_COLUMNS)
    return f"{'case':<27}{'RTF':>8}{'frames/s':>10}  µs/frame:{parts}{'total':>8}"


def _budget_row(budget: FrameBudget) -> str:
    parts = "".join(f"{getattr(budget, name):8.1f}" for _, name in BUDGET_COLUMNS)
    return f"{parts}{budget.total_us:8.1f}"


def _print_before() -> None:
    for label, (parts_us, rtf) in BEFORE.items():
        budget = FrameBudget(*map(float, parts_us))
        print(f"{label:<27}{rtf:7.1f}x{'before':>10}  {' ' * 9}{_budget_row(budget)}")


def _case(sensor_layer: str, imu_hz: int, autopilot: str) -> None:
    label = f"{sensor_layer} IMU {imu_hz:>4} Hz {autopilot}"
    try:
        result = _fly(sensor_layer, imu_hz, autopilot, SIMULATED_S[sensor_layer])
    except RigError as error:
        print(f"{label:<27}  failed: {error}", flush=True)
        return
    print(
        f"{label:<27}{result.real_time_factor:7.2f}x{result.frames / result.wall_s:10.0f}"
        f"  {' ' * 9}{_budget_row(result.budget)}",
        flush=True,
    )


def _own_peak_rss_mib() -> float:
    """This process's peak RSS (VmHWM of its own memory map).

    Not ``ru_maxrss``: Linux carries a parent's peak across fork and exec, so under
    ``python -m benchmarks`` (which has just held the credibility benchmark's data) this
    process would report its parent's size.
    """
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024  # kB
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # not Linux


def _children_peak_rss_mib() -> float:
    """The largest peak RSS of the waited-for children (the autopilot, forked from this
    process while it was small)."""
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024  # KiB on Linux


def peak_rss() -> None:
    """One 60 s TLM run at 1 kHz with the reference autopilot; peak RSS of both processes."""
    early_mib: list[float] = []

    def first_progress(progress: Progress) -> None:
        if not early_mib:
            early_mib.append(_own_peak_rss_mib())

    result = _fly("tlm", 1000, "reference", PEAK_RSS_SIMULATED_S, first_progress)
    # The autopilot is the rig's only (waited-for) child process.
    print(
        f"peak RSS of a {result.simulated_s:.0f} s TLM run (1 kHz IMU, reference autopilot, "
        f"RTF {result.real_time_factor:.2f}x): rig {early_mib[0]:.0f} MiB after 0.1 s, "
        f"{_own_peak_rss_mib():.0f} MiB after {result.simulated_s:.0f} s; "
        f"autopilot {_children_peak_rss_mib():.0f} MiB",
        flush=True,
    )


#: ``make hil-sim``'s flight (rig/scenarios/hil_sim.toml), for the projected wall time.
HIL_SIM_S = 60.0
RTL_TICK_INSTANCE = INSTANCE + 1  # its own ports: the cases above may still be closing


def rtl_pwm_tick_cases() -> None:
    """RTL layer, reference autopilot: IMU 1 kHz / 250 Hz × PWM capture tick 1 µs / 4 µs.

    The capture clock runs all the time in the RTL layer (one simulated cycle per tick),
    so the tick sets much of the co-simulation's cost; these figures choose hil_sim's
    rates. The last column is the 60 s hil_sim flight's wall time at that RTF.
    """
    print(f"{'rtl case (reference autopilot)':<34}{'RTF':>8}{'chips µs/frame':>16}"
          f"{'hil_sim 60 s takes':>20}")  # fmt: skip
    for imu_hz in (1000, 250):
        for tick_hz in (1_000_000, 250_000):
            label = f"IMU {imu_hz:>4} Hz, PWM tick {1e6 / tick_hz:g} µs"
            scenario = scenario_from_dict(
                {
                    "name": "bench_rtl_tick", "vehicle": "f450_high_precision",
                    "duration_s": SIMULATED_S["rtl"], "seed": 1, "sensor_layer": "rtl",
                    "rates": {"imu_hz": imu_hz, "pwm_tick_hz": tick_hz},
                    "commands": [{"at_s": 0.5, "action": "arm"},
                                 {"at_s": 0.6, "action": "takeoff", "altitude_m": 2.0}],
                }
            )  # fmt: skip
            try:
                with tempfile.TemporaryDirectory() as folder:
                    options = RunOptions(
                        instance=RTL_TICK_INSTANCE, out_dir=Path(folder),
                        timeouts=LinkTimeouts(connect_s=600, answer_s=30),
                    )  # fmt: skip
                    result = run_scenario(scenario, options)
            except RigError as error:
                print(f"{label:<34}  failed: {error}", flush=True)
                continue
            rtf = result.real_time_factor
            print(f"{label:<34}{rtf:7.2f}x{result.budget.chips_us:16.0f}"
                  f"{HIL_SIM_S / rtf:18.0f} s", flush=True)  # fmt: skip


def main() -> None:
    autopilots = ["double"]
    if importlib.util.find_spec("rig.autopilots.reference.__main__") is not None:
        autopilots.insert(0, "reference")
    else:
        print("(reference autopilot not installed: `rig.autopilots.reference` is missing)")
    print(_budget_heading())
    _print_before()
    for sensor_layer in ("tlm", "rtl"):
        for imu_hz in (1000, 250):
            for autopilot in autopilots:
                _case(sensor_layer, imu_hz, autopilot)
    print("targets: rtl >= 1.0x, tlm >= 20x real time (2 cores)")
    rtl_pwm_tick_cases()
    # A fresh process, so the peak is this run's and not the cases' above.
    subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_rig", "--peak-rss"], check=True, cwd=REPO
    )


if __name__ == "__main__":
    if sys.argv[1:] == ["--peak-rss"]:
        peak_rss()
    elif sys.argv[1:] == ["--rtl-pwm-tick"]:
        rtl_pwm_tick_cases()
    else:
        main()
