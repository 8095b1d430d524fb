"""``rig replay`` speed: planning the real X500 log, and flying its drives through the rig.

Each drive flies 407.4 → 417 s of the log (armed idle, the take-off, the climb) with the
reference autopilot on the TLM layer at 1 kHz; ``rates`` and ``attitude`` take over for
415-416 s. Every setpoint travels in an acknowledged conversation (DO_SET_MODE after it), so
the drives differ by their setpoint rate: 10 Hz velocity, 20 Hz attitude, 50 Hz rates. The
figures show what a replay costs beside a plain run of the same length (``bench_rig``).
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from benchmarks.figures import Figure, budget_detail
from rig.lockstep.loop import RunOptions
from rig.mavlink.px4_api import free_instance
from rig.replay import ReplayOptions, plan_replay, run_replay

X500_LOG = (
    Path(__file__).resolve().parent.parent
    / "data"
    / "flight_logs"
    / "px4_x500v2_v6xrt_flight_2026-03-20.ulg"
)
END_S = 417.0
WINDOW_S = (415.0, 416.0)
PLANS = 5


def figures() -> Iterator[Figure]:
    started = time.perf_counter()
    for _ in range(PLANS):
        plan_replay(X500_LOG)
    planning = (time.perf_counter() - started) / PLANS
    yield Figure("plan_replay, the whole X500 log (3.5 MB)", planning, "s")
    with tempfile.TemporaryDirectory() as folder:
        for drive in ("velocity", "rates", "attitude"):
            window = None if drive == "velocity" else WINDOW_S
            plan = plan_replay(X500_LOG, ReplayOptions(drive=drive, end_s=END_S, window_s=window))
            options = RunOptions(instance=free_instance(60, 40), out_dir=Path(folder) / drive)
            result = run_replay(plan, options)
            yield Figure(f"replay, {drive} drive", result.real_time_factor, "× real time",
                         detail=f"{result.simulated_s:.1f} s simulated; "
                         f"{budget_detail(result.budget)}")  # fmt: skip
