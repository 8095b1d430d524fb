"""Time and peak memory of `rig identify` on the real X500 log (97 s, 50 Hz rate topics):
reading, hover detection, the thrust-stand torque derivative and four rate-loop fits."""

import resource
import time
from pathlib import Path

from quad_model.vehicle import load_vehicle
from rig.apps.identify import identify_vehicle

LOG = (
    Path(__file__).resolve().parent.parent
    / "data/flight_logs/px4_x500v2_v6xrt_flight_2026-03-20.ulg"
)
WINDOW_S = (455.0, 481.5)
REPEATS = 3


def main() -> None:
    vehicle = load_vehicle("x500_v2")
    start = time.perf_counter()
    identify_vehicle(LOG, vehicle, WINDOW_S)  # numba kernels compiled or loaded from cache
    first_s = time.perf_counter() - start
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        identify_vehicle(LOG, vehicle, WINDOW_S)
        times.append(time.perf_counter() - start)
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"identify {LOG.name} ({LOG.stat().st_size / 1e6:.1f} MB): "
          f"best {min(times):.2f} s, median {sorted(times)[REPEATS // 2]:.2f} s "
          f"of {REPEATS} (first call {first_s:.2f} s); peak RSS {peak_mib:.0f} MiB")  # fmt: skip


if __name__ == "__main__":
    main()
