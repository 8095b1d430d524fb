"""``make soak``: a day of simulated flight in one run, to show that nothing grows or drifts.

One closed-loop run (TLM chips, IMU 250 Hz, the reference autopilot, as fast as it goes)
flies a short hop at the start of every simulated hour — arm, take off to 3 m, hover,
land — and idles on the ground in between, with the F450's pack draining as it would
(a day is far longer than the pack: late hops may not leave the ground, which the table
shows). Every simulated hour it prints the rig's and the autopilot's resident memory; at
the end the growth per simulated hour, and whether both logs read back whole with every
sensor slot in place.

``python -m benchmarks.soak --hours 24`` (``make soak``, about 3 hours here);
``--hours 1`` for a quick look. Prints figures; it fails (exit 1) only on what the issue
counts as a failure: a traceback, a hang, an unreadable log, a missed sensor slot.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyulog
from rich.console import Console
from rich.table import Table

from rig.errors import RigError
from rig.lockstep.loop import Progress, RunOptions, run_scenario
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import Scenario, scenario_from_dict

IMU_HZ = 250
OUT_DIR = Path(__file__).resolve().parent.parent / "build" / "soak"


def soak_scenario(hours: int) -> Scenario:
    """A hop (Hold, arm, take off to 3 m, hover 30 s, land) at the start of every hour;
    Hold first, as a pilot switches out of Land (where PX4 refuses to arm) before a flight."""
    commands = []
    for hour in range(hours):
        start_s = hour * 3600.0 + 5.0
        commands += [{"at_s": start_s - 1.0, "action": "hold"},
                     {"at_s": start_s, "action": "arm"},
                     {"at_s": start_s + 0.5, "action": "takeoff", "altitude_m": 3.0},
                     {"at_s": start_s + 30.0, "action": "land"}]  # fmt: skip
    return scenario_from_dict({
        "name": "soak", "description": f"{hours} h: a hop every hour, idle between",
        "vehicle": "f450_high_precision", "duration_s": hours * 3600.0, "seed": 24,
        "sensor_layer": "tlm", "rates": {"imu_hz": IMU_HZ},
        "commands": commands,
    })  # fmt: skip


def rss_mib(pid: int | str = "self") -> float:
    """Resident memory now (VmRSS) of a process, 0 when it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0.0
    for line in status.splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024  # kB
    return 0.0


def child_pids() -> list[int]:
    """This process's children (the autopilot), from /proc."""
    pids = []
    for task in Path("/proc/self/task").iterdir():
        pids += [int(pid) for pid in (task / "children").read_text().split()]
    return pids


@dataclass(frozen=True)
class HourMark:
    hour: int
    wall_s: float
    real_time_factor: float
    altitude_m: float
    rig_mib: float
    autopilot_mib: float


class Recorder:
    """The progress callback: one :class:`HourMark` per simulated hour, printed as it comes."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self.marks: list[HourMark] = []
        self.peak_altitude_m = 0.0
        self._wall_start = time.monotonic()

    def __call__(self, progress: Progress) -> None:
        self.peak_altitude_m = max(self.peak_altitude_m, progress.altitude_m)
        hour = len(self.marks) + 1
        if progress.time_s < hour * 3600.0:
            return
        wall_s = time.monotonic() - self._wall_start
        mark = HourMark(hour, wall_s, progress.real_time_factor, self.peak_altitude_m,
                        rss_mib(), sum(map(rss_mib, child_pids())))  # fmt: skip
        self.marks.append(mark)
        self.peak_altitude_m = 0.0
        self.console.print(
            f"hour {hour:3d}: wall {wall_s / 60:6.1f} min, RTF {mark.real_time_factor:5.2f}x, "
            f"highest {mark.altitude_m:4.1f} m, RSS rig {mark.rig_mib:6.1f} MiB, "
            f"autopilot {mark.autopilot_mib:6.1f} MiB", highlight=False,
        )  # fmt: skip


def growth_mib_per_hour(hours: list[int], mib: list[float]) -> float:
    """Least-squares slope after the first hour (imports, caches and buffers fill first)."""
    if len(hours) < 3:
        return float("nan")
    return float(np.polyfit(hours[1:], mib[1:], 1)[0])


def check_logs(rig_log: Path, autopilot_log: Path | None, hours: int) -> list[str]:
    """What is wrong with the logs: unreadable, cut short, a sensor slot missing."""
    problems = []
    # The IMU is sampled every frame (about 1 GiB of memory to read a day of it).
    log = pyulog.ULog(str(rig_log), ["sensor_combined"])
    if log.file_corruption:
        problems.append(f"{rig_log}: corrupt")
    imu_us = log.get_dataset("sensor_combined").data["timestamp"].astype(np.int64)
    expected = hours * 3600 * IMU_HZ
    if imu_us.size != expected or set(np.diff(imu_us).tolist()) != {1_000_000 // IMU_HZ}:
        problems.append(f"{rig_log}: {imu_us.size} IMU samples, expected {expected} on a "
                        f"{1000 // IMU_HZ} ms grid")  # fmt: skip
    if autopilot_log is None:
        problems.append("no autopilot log")
    else:
        autopilot = pyulog.ULog(str(autopilot_log), ["vehicle_status"])
        last_s = autopilot.get_dataset("vehicle_status").data["timestamp"][-1] / 1e6
        if autopilot.file_corruption or last_s < hours * 3600 - 0.1:
            problems.append(f"{autopilot_log}: corrupt or ends at {last_s:.0f} s")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="soak", description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=int, default=24, help="simulated hours (default 24)")
    parser.add_argument("--out", type=Path, default=OUT_DIR, help=f"run folder (default {OUT_DIR})")
    args = parser.parse_args(argv)
    console = Console()
    console.print(f"soak: {args.hours} simulated h, TLM chips, IMU {IMU_HZ} Hz, reference "
                  f"autopilot; logs in {args.out}", highlight=False)  # fmt: skip
    recorder = Recorder(console)
    options = RunOptions(out_dir=args.out, timeouts=LinkTimeouts(connect_s=60, answer_s=30))
    try:
        result = run_scenario(soak_scenario(args.hours), options, recorder)
    except RigError as error:  # the run's end is the finding: its logs stay readable
        console.print(f"[red]failure[/]: the run ended early: {error}", highlight=False)
        return 1
    problems = check_logs(result.rig_log, result.autopilot_log, args.hours)
    hours = [mark.hour for mark in recorder.marks]
    table = Table(title=f"soak: {result.simulated_s / 3600:.1f} simulated h", title_justify="left")
    for column in ("figure", "value", "unit"):
        table.add_column(column, justify="right" if column == "value" else "left")
    rows = (
        ("wall time", result.wall_s / 60, "min"),
        ("real-time factor", result.real_time_factor, "× real time"),
        ("frames", result.frames, "frames"),
        ("rig RSS at the end", recorder.marks[-1].rig_mib, "MiB"),
        ("rig RSS growth", growth_mib_per_hour(hours, [m.rig_mib for m in recorder.marks]),
         "MiB per simulated h"),
        ("autopilot RSS growth",
         growth_mib_per_hour(hours, [m.autopilot_mib for m in recorder.marks]),
         "MiB per simulated h"),
        ("rig.ulg", result.rig_log.stat().st_size / 2**20, "MiB"),
        ("failures (tracebacks, hangs, unreadable logs, missed slots)", len(problems), ""),
    )  # fmt: skip
    for name, value, unit in rows:
        if isinstance(value, float) and math.isnan(value):  # a growth from fewer than 3 hours
            table.add_row(name, "—", f"{unit} (needs 3 simulated hours)")
        else:
            table.add_row(name, f"{value:,.2f}" if isinstance(value, float) else f"{value:,}",
                          unit)  # fmt: skip
    console.print(table)
    for problem in problems:
        console.print(f"[red]failure[/]: {problem}", highlight=False)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
