"""One measured figure of a benchmark, and how ``make bench`` shows it.

Each ``benchmarks/bench_*.py`` yields :class:`Figure`s from ``figures()``;
``python -m benchmarks`` runs them, sends whatever the tools print (Verilator, cocotb,
PX4) to ``build/bench/<module>.log`` and prints one table.
"""

from __future__ import annotations

import math
import resource
from dataclasses import dataclass
from pathlib import Path

from rig.lockstep.loop import FrameBudget, RunResult

#: Parts of a lockstep frame's wall time, as the budget column shows them.
BUDGET_PARTS = (
    ("model", "model_us"), ("sensors", "sensor_physics_us"), ("chips", "chips_us"),
    ("mavlink", "mavlink_us"), ("send", "socket_send_us"), ("wait", "autopilot_wait_us"),
    ("log", "logging_us"), ("other", "other_us"),
)  # fmt: skip


@dataclass(frozen=True)
class Figure:
    """``value`` in ``unit``; ``goal`` as the issue states it; ``detail`` what it is made of."""

    name: str
    value: float
    unit: str
    goal: str = ""
    detail: str = ""

    def shown(self) -> str:
        """The value with as many digits as it deserves."""
        magnitude = abs(self.value)
        digits = ",.0f" if magnitude >= 100 else ".1f" if magnitude >= 10 else ".2f"
        return f"{self.value:{digits}}"


def budget_detail(budget: FrameBudget) -> str:
    """A frame's wall time by part, µs: where a real-time factor comes from; and the
    whole as a multiple of the model's part.

    The model's part is fixed compiled work, so it measures the machine's pace over the
    same frames. On a shared virtual machine one core's pace moves by half within a
    minute: repeated flights of one commit read 1.56–2.49× real time (RTL, IMU 1 kHz)
    while their frame stayed 14.3–15.4 times the model's part. Between commits, that
    multiple tells a cheaper frame from a faster machine.
    """
    parts = " · ".join(f"{label} {getattr(budget, name):.0f}" for label, name in BUDGET_PARTS)
    multiple = budget.total_us / budget.model_us if budget.model_us > 0 else math.nan
    return f"µs/frame: {parts} = {budget.total_us:.0f} ({multiple:.1f}× model)"


def chips_detail(result: RunResult) -> str:
    """The compiled chips' share of a frame by kind of call (µs and clock cycles per frame,
    the capture's in ticks, of which it clocks only the edges with work): the per-frame
    budget of the RTL, measured inside the simulator library."""
    frames = max(result.frames, 1)
    parts = [
        f"{cost.what} {cost.seconds / frames * 1e6:.0f} µs / {cost.cycles / frames:.0f} "
        f"{cost.clock} cycles ({cost.seconds / max(cost.cycles, 1) * 1e9:.0f} ns each)"
        for cost in sorted(result.chip_costs, key=lambda c: -c.seconds)
        if cost.calls
    ]
    return "chips per frame: " + " · ".join(parts) if parts else ""


def late_detail(result: RunResult) -> str:
    """How often the autopilot set a frame's pace: its answer was not there yet when the
    rig, its own work for the frame done, asked for it (the two share the machine's cores,
    so such a frame is the autopilot's compute, not the rig's work)."""
    link = result.link
    if not link.answers:
        return ""
    late = f"autopilot's answer late in {link.late_answers:,} of {link.answers:,} frames"
    if not link.late_answers:
        return late
    return f"{late}, {link.late_wait_s / link.late_answers * 1e6:.0f} µs each"


def run_detail(result: RunResult) -> str:
    """A flown case's detail: its frame budget, how often the autopilot set the pace, and
    the compiled chips' share (RTL)."""
    parts = [budget_detail(result.budget), late_detail(result), chips_detail(result)]
    return "; ".join(filter(None, parts))


def lowest_of(runs: list[Figure], goal: str = "") -> Figure:
    """Repeated runs of one figure as one: the lowest value (a goal counts the low end of
    the spread), the spread and the lowest run's detail."""
    failed = [run for run in runs if math.isnan(run.value)]
    if failed:
        return failed[0]
    low = min(runs, key=lambda run: run.value)
    values = ", ".join(f"{run.value:.2f}" for run in sorted(runs, key=lambda run: run.value))
    spread = f"lowest of {len(runs)} runs ({values})"
    return Figure(low.name, low.value, low.unit, goal, f"{spread}; {low.detail}")


def peak_rss_mib() -> float:
    """This process's peak RSS (VmHWM of its own memory map).

    Not ``ru_maxrss``: Linux carries a parent's peak across fork and exec, so a benchmark
    started by ``python -m benchmarks`` (which has just held other benchmarks' data) would
    report its parent's size.
    """
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024  # kB
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # not Linux
