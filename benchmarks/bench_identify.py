"""Time and peak memory of `rig identify` on the real X500 log (97 s, 50 Hz rate topics):
reading, hover detection, the thrust-stand torque derivative and four rate-loop fits."""

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from benchmarks.figures import Figure, peak_rss_mib
from px4_logs import FlightLog
from quad_model.vehicle import load_vehicle
from rig.identify import identify_vehicle

LOG = (
    Path(__file__).resolve().parent.parent
    / "data/flight_logs/px4_x500v2_v6xrt_flight_2026-03-20.ulg"
)
WINDOW_S = (455.0, 481.5)
REPEATS = 3


def measure() -> dict[str, float]:
    """Times of a first and of repeated calls, and this process's peak RSS."""
    vehicle = load_vehicle("x500_v2")
    start = time.perf_counter()
    identify_vehicle(
        FlightLog.read(LOG), vehicle, WINDOW_S
    )  # numba kernels compiled or loaded from cache
    first_s = time.perf_counter() - start
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        identify_vehicle(FlightLog.read(LOG), vehicle, WINDOW_S)
        times.append(time.perf_counter() - start)
    return {
        "first_s": first_s,
        "best_s": min(times),
        "median_s": sorted(times)[REPEATS // 2],
        "peak_rss_mib": peak_rss_mib(),
    }


def figures() -> Iterator[Figure]:
    # A fresh process, so the peak memory is identify's own.
    measured = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_identify"],
        check=True, cwd=Path(__file__).resolve().parent.parent, capture_output=True, text=True,
    )  # fmt: skip
    figures = json.loads(measured.stdout.splitlines()[-1])
    log = f"{LOG.name} ({LOG.stat().st_size / 1e6:.1f} MB)"
    yield Figure(f"rig identify {log}", figures["best_s"], "s",
                 detail=f"best of {REPEATS}; median {figures['median_s']:.2f} s; "
                 f"first call {figures['first_s']:.2f} s")  # fmt: skip
    yield Figure("rig identify, peak RSS", figures["peak_rss_mib"], "MiB", goal="≤ 300 MiB")


if __name__ == "__main__":
    print(json.dumps(measure()))
