"""Campaign throughput: cases per wall minute for a 30 s scenario, pool vs Dask, 1 vs 2 workers.

Each case flies ``takeoff_hover_land`` (30 s, TLM chips, IMU at 1 kHz, the reference
autopilot) in its own process, as ``rig campaign`` does. Figures only (target from the
issue: ≥ 1.8× from 1 to 2 workers). On 2 cores the ceiling is lower than the worker
count suggests: one case is already two processes (the rig and its autopilot) that take
turns in lockstep, so a single case keeps more than one core partly busy.

Four cases per configuration.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from dask.distributed import LocalCluster

from benchmarks.figures import Figure
from rig.campaign import campaign_executor, campaign_from_dict, run_campaign

CASES = 4


def _campaign(cases: int):
    return campaign_from_dict(
        {"name": "bench", "scenario": "takeoff_hover_land", "sensor_layer": "tlm",
         "axes": {"seed": list(range(1, cases + 1))}},
        "bench_campaign",
    )  # fmt: skip


def _rate(
    cases: int, workers: int | None, scheduler: str | None = None
) -> tuple[float, float, int]:
    """(cases per wall minute, mean case wall time in s, cases that did not run) for one
    fresh campaign run."""
    with tempfile.TemporaryDirectory() as folder:
        started = time.monotonic()
        with campaign_executor(scheduler, workers) as executor:
            results = run_campaign(_campaign(cases), Path(folder), executor)
        wall_s = time.monotonic() - started
    bad = sum(r.status not in ("ok", "failed") for r in results)
    return len(results) / wall_s * 60.0, sum(r.wall_s for r in results) / len(results), bad


def figures() -> Iterator[Figure]:
    rates = {}
    for label, workers in (("local pool, 1 worker", 1), ("local pool, 2 workers", 2)):
        rates[label] = _rate(CASES, workers)
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None)  # fmt: skip
    with cluster:
        rates["Dask LocalCluster, 2 workers"] = _rate(CASES, None, cluster.scheduler_address)
    for label, (per_minute, case_s, bad) in rates.items():
        detail = f"{CASES} cases of takeoff_hover_land (30 s, TLM); mean case wall {case_s:.1f} s"
        if bad:
            detail += f"; {bad} did not run"
        yield Figure(f"campaign, {label}", per_minute, "cases/min", detail=detail)
    one, two = rates["local pool, 1 worker"][0], rates["local pool, 2 workers"][0]
    yield Figure("campaign scaling, 1 → 2 workers (local pool)", two / one, "×", goal="≥ 1.8×")
