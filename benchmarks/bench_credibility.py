"""Time to score a 30-minute, 1 kHz log pair with all three test kinds (target ≤ 5 s).

The pair is synthetic: a known first-order plant driven by white noise, with sensor-like
noise and a step, written to Parquet in a temporary directory. The "sim" log differs by a
gain, an offset and a clock lag, so every stage (reading, windowing, alignment, spectra,
report rendering) does real work.
"""

import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import signal as sps

from benchmarks.figures import Figure
from credibility.assess import assess
from credibility.plan import load_plan
from credibility.report import write_report

RATE_HZ = 1000.0
DURATION_S = 1800.0

PLAN = """
[plan]
name = "benchmark: 30 min at 1 kHz"
[weights]
performance = 0.3
time = 0.3
frequency = 0.4
[logs]
real = "real.parquet"
sim = "sim.parquet"

[[tests]]
name = "noise_sigma"
kind = "performance"
parameter = "std"
signal = "imu.noise"
segment_s = [10.0, 1790.0]
highpass_hz = 5.0

[[tests]]
name = "step_settling"
kind = "performance"
parameter = "settling_time"
signal = "imu.step"
segment_s = [900.0, 960.0]

[[tests]]
name = "response_curve"
kind = "time"
signal = "plant.y"
segment_s = [100.0, 1700.0]
align = { method = "xcorr", max_lag_s = 1.0 }

[[tests]]
name = "plant_response"
kind = "frequency"
input = "plant.u"
output = "plant.y"
segment_s = [0.0, 1790.0]
band_hz = [0.1, 100.0]
n_points = 50
"""


def _write_logs(directory: Path, rng: np.random.Generator) -> None:
    t = np.arange(0.0, DURATION_S, 1.0 / RATE_HZ)
    u = rng.standard_normal(t.size)
    b, a = sps.butter(1, 5.0, fs=RATE_HZ)  # the plant: a 5 Hz first-order lag
    for name, gain, lag_s, noise in (("real", 1.0, 0.0, 0.10), ("sim", 1.1, 0.25, 0.11)):
        shift = int(lag_s * RATE_HZ)
        u_run = np.roll(u, shift)
        step = 1.0 - np.exp(-np.clip(t - 900.0 - lag_s, 0.0, None) / 0.5)
        pd.DataFrame(
            {
                "time_s": t,
                "plant.u": u_run,
                "plant.y": gain * sps.lfilter(b, a, u_run),
                "imu.noise": noise * rng.standard_normal(t.size),
                "imu.step": step + 0.001 * rng.standard_normal(t.size),
            }
        ).to_parquet(directory / f"{name}.parquet")


def figures() -> Iterator[Figure]:
    rng = np.random.default_rng(2024)
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp)
        _write_logs(directory, rng)
        plan_path = directory / "plan.toml"
        plan_path.write_text(PLAN)
        start = time.perf_counter()
        assessment = assess(load_plan(plan_path))
        scored = time.perf_counter() - start
        start = time.perf_counter()
        write_report(assessment, directory / "out")
        rendered = time.perf_counter() - start
        size_mb = sum(p.stat().st_size for p in directory.glob("*.parquet")) / 1e6
    samples = int(DURATION_S * RATE_HZ)
    yield Figure(
        "score a 30 min, 1 kHz log pair (read + 4 tests of all three kinds)", scored, "s",
        detail=f"2 × {samples:,} rows × 4 signals, {size_mb:.0f} MB Parquet; "
        f"η_all {assessment.eta_all:.3f}, η_min {assessment.eta_min:.3f}",
    )  # fmt: skip
    yield Figure("render the report (HTML + JSON)", rendered, "s")
    yield Figure("score + render", scored + rendered, "s", goal="≤ 5 s")
