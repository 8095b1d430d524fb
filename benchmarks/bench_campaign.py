"""Campaign throughput: cases per wall minute for a 30 s scenario, pool vs Dask, 1 vs 2 workers.

Each case flies ``takeoff_hover_land`` (30 s, TLM chips, IMU at 1 kHz, the reference
autopilot) in its own process, as ``rig campaign`` does. Figures only (target from the
issue: ≥ 1.8× from 1 to 2 workers). On 2 cores the ceiling is lower than the worker
count suggests: one case is already two processes (the rig and its autopilot) that take
turns in lockstep, so a single case keeps more than one core partly busy.

``python -m benchmarks.bench_campaign [CASES]`` (default 4 cases per configuration).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from dask.distributed import LocalCluster

from rig.apps.campaign import campaign_executor, campaign_from_dict, run_campaign

DEFAULT_CASES = 4


def _campaign(cases: int):
    return campaign_from_dict(
        {"name": "bench", "scenario": "takeoff_hover_land", "sensor_layer": "tlm",
         "axes": {"seed": list(range(1, cases + 1))}},
        "bench_campaign",
    )  # fmt: skip


def _rate(cases: int, workers: int | None, scheduler: str | None = None) -> tuple[float, float]:
    """(cases per wall minute, mean case wall time in s) for one fresh campaign run."""
    with tempfile.TemporaryDirectory() as folder:
        started = time.monotonic()
        with campaign_executor(scheduler, workers) as executor:
            results = run_campaign(_campaign(cases), Path(folder), executor)
        wall_s = time.monotonic() - started
    bad = [r for r in results if r.status not in ("ok", "failed")]
    if bad:
        print(f"  ({len(bad)} cases did not run: {bad[0].reason})")
    return len(results) / wall_s * 60.0, sum(r.wall_s for r in results) / len(results)


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    cases = int(args[0]) if args else DEFAULT_CASES
    print(f"{cases} cases of takeoff_hover_land (30 s, TLM) per configuration")
    figures = {}
    for label, workers in (("local pool, 1 worker", 1), ("local pool, 2 workers", 2)):
        figures[label] = _rate(cases, workers)
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None)  # fmt: skip
    with cluster:
        figures["Dask LocalCluster, 2 workers"] = _rate(cases, None, cluster.scheduler_address)
    for label, (per_minute, case_s) in figures.items():
        print(f"{label:30s} {per_minute:6.2f} cases/min   mean case wall {case_s:5.1f} s")
    one, two = figures["local pool, 1 worker"][0], figures["local pool, 2 workers"][0]
    print(f"scaling 1 -> 2 workers (local pool): {two / one:.2f}x (target >= 1.8x)")


if __name__ == "__main__":
    main()
