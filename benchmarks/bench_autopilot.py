"""Frames per second of the reference autopilot's core, ``FlightController.update``.

The rig targets ≥ 20× real time at a 1 kHz IMU, so one frame must cost well under 0.5 ms.
Measured here with the whole cascade running (armed, taking off: estimation, position loop
at 50 Hz, attitude and rate loops and allocation every frame), with and without the ULog,
on synthetic sensors at rest (the cost does not depend on the motion).

Measured on the 2-core CI machine kind (shared CPU, ±20 %): before the per-frame path was
compiled, 127-190 µs/frame without the log; with the numba kernels (attitude filter, Kalman
prediction, gyro filters, attitude and rate control, allocation), 34 µs without and 42 µs
with the ULog. What remains is the Python glue of the commander and the frame bookkeeping.
"""

from __future__ import annotations

import math
import tempfile
import time
import tracemalloc
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from benchmarks.figures import Figure
from quad_model.frames import ned_to_geodetic
from rig.autopilots.reference import FlightController, GpsFix, Parameters, SensorFrame
from rig.autopilots.reference.flight_log import open_flight_log

HOME = (47.397742, 8.545594, 488.0)
IMU_RATE_HZ = 1000
FRAMES = 20_000


def _frames(count: int, rng: np.random.Generator) -> list[SensorFrame]:
    """IMU every frame, mag 100 Hz, baro 50 Hz, GPS 10 Hz, with white noise."""
    frames = []
    for k in range(count):
        n = rng.standard_normal
        gps = None
        if k % 100 == 0:
            lat, lon, alt = ned_to_geodetic(n(3) * 0.3, *HOME)
            gps = GpsFix(lat, lon, alt, (0.0, 0.0, 0.0), 0.8, 1.2, 3, 12)
        frames.append(SensorFrame(
            accel_mps2=np.array([0.0, 0.0, -9.80665]) + n(3) * 0.05,
            gyro_radps=n(3) * 0.003,
            mag_gauss=np.array([0.215, 0.0133, 0.4329]) + n(3) * 0.002 if k % 10 == 0 else None,
            baro_pressure_pa=95_500.0 + n() if k % 20 == 0 else None,
            baro_temperature_degc=15.0 if k % 20 == 0 else None,
            gps=gps,
        ))  # fmt: skip
    return frames


def _run(controller: FlightController, frames: list[SensorFrame], start_us: int) -> float:
    period_us = 1_000_000 // IMU_RATE_HZ
    begin = time.perf_counter()
    for k, frame in enumerate(frames):
        controller.update(frame, start_us + k * period_us)
    return time.perf_counter() - begin


def _flying_controller(log_path: Path | None) -> tuple[FlightController, int]:
    params = Parameters()
    log = open_flight_log(log_path, params.as_dict()) if log_path else None
    controller = FlightController(params, log)
    warmup = _frames(3 * IMU_RATE_HZ, np.random.default_rng(1))
    _run(controller, warmup, 1)
    controller.takeoff(math.nan)
    assert controller.arm().result == 0, controller.preflight_failure()
    return controller, 1 + len(warmup) * (1_000_000 // IMU_RATE_HZ)


def figures() -> Iterator[Figure]:
    frames = _frames(FRAMES, np.random.default_rng(2))
    with tempfile.TemporaryDirectory() as folder:
        for label, log_path in (("no log", None), ("with ULog", Path(folder) / "bench.ulg")):
            controller, start_us = _flying_controller(log_path)
            seconds = _run(controller, frames, start_us)
            rate = FRAMES / seconds
            detail = f"{1e6 / rate:.0f} µs/frame, {rate / IMU_RATE_HZ:.1f}× real time at 1 kHz"
            if controller.log is not None:
                controller.log.close()
                size_kib = log_path.stat().st_size / 1024
                detail += f"; ULog {size_kib / (FRAMES / IMU_RATE_HZ):.0f} KiB per simulated s"
            yield Figure(f"FlightController.update, {label}", rate, "frames/s", detail=detail)
    controller, start_us = _flying_controller(None)
    tracemalloc.start()
    _run(controller, frames[:5000], start_us)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    yield Figure("peak Python memory over 5000 frames", peak / 1024, "KiB")
