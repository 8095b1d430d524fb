"""One measured figure of a benchmark, and how ``make bench`` shows it.

Each ``benchmarks/bench_*.py`` yields :class:`Figure`s from ``figures()``;
``python -m benchmarks`` runs them, sends whatever the tools print (Verilator, cocotb,
PX4) to ``build/bench/<module>.log`` and prints one table.
"""

from __future__ import annotations

import resource
from dataclasses import dataclass
from pathlib import Path

from rig.lockstep.loop import FrameBudget

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
    """A frame's wall time by part, µs: where a real-time factor comes from."""
    parts = " · ".join(f"{label} {getattr(budget, name):.0f}" for label, name in BUDGET_PARTS)
    return f"µs/frame: {parts} = {budget.total_us:.0f}"


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
