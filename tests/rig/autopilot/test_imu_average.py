"""``sensor_combined`` as PX4 logs it: the IMU averaged over IMU_INTEG_RATE intervals."""

import math

import numpy as np
import pytest

from rig.autopilots.reference.flight_log import ImuAverage

IMU_HZ = 1000
FRAME_US = 1_000_000 // IMU_HZ


def _average(samples: np.ndarray, rate_hz: float, frame_us: int = FRAME_US):
    """Feed ``samples`` (n × 3) as gyro and accelerometer; the intervals it closes."""
    average = ImuAverage(rate_hz)
    intervals = []
    for k, sample in enumerate(samples):
        interval = average.add(1_000_000 + k * frame_us, sample, -sample)
        if interval is not None:
            intervals.append(interval)
    return intervals


def test_white_noise_drops_by_the_root_of_the_samples_per_interval():
    """σ = 0.01 rad/s white noise at 1 kHz, averaged over 5 ms (200 Hz): σ/√5. With 40 000
    intervals the estimated σ has a relative standard error of 1/√(2·40 000) = 0.35 %; 2 %
    is more than five of those."""
    sigma = 0.01
    samples = np.random.default_rng(3).normal(0.0, sigma, (200_001, 3))
    intervals = _average(samples, 200)
    assert len(intervals) == 40_000
    assert {i.integral_dt_us for i in intervals} == {5000}
    gyro = np.array([i.gyro_radps for i in intervals])
    accel = np.array([i.accel_mps2 for i in intervals])
    np.testing.assert_allclose(gyro.std(axis=0), sigma / math.sqrt(5), rtol=0.02)
    np.testing.assert_allclose(accel.std(axis=0), sigma / math.sqrt(5), rtol=0.02)
    # each interval is the mean of exactly its five samples (the first only starts the clock)
    np.testing.assert_allclose(gyro[0], samples[1:6].mean(axis=0), rtol=1e-12)


def test_a_constant_passes_unchanged():
    value = np.array([0.1, -0.2, 9.81])
    (first, *rest) = _average(np.tile(value, (101, 1)), 200)
    for interval in (first, *rest):
        np.testing.assert_allclose(interval.gyro_radps, value, rtol=1e-15)
        np.testing.assert_allclose(interval.accel_mps2, -value, rtol=1e-15)
    assert len(rest) == 19
    assert first.time_us == 1_000_000 + 5 * FRAME_US


@pytest.mark.parametrize(
    ("imu_hz", "rate_hz", "samples_per_interval"),
    [(1000, 250, 4), (1000, 100, 10), (250, 200, 1), (500, 200, 2)],
)
def test_intervals_hold_the_whole_samples_nearest_the_rate(imu_hz, rate_hz, samples_per_interval):
    """PX4 closes an interval at the sample nearest 1/IMU_INTEG_RATE: a 250 Hz IMU under the
    200 Hz default publishes every sample (4 ms), a 500 Hz one every second (4 ms too)."""
    frame_us = 1_000_000 // imu_hz
    intervals = _average(np.zeros((41, 3)), rate_hz, frame_us)
    assert {i.integral_dt_us for i in intervals} == {samples_per_interval * frame_us}
