"""What the autopilot receives from the simulator, in SI units, and how it judges freshness.

The process wrapper turns PX4's simulator messages (HIL_SENSOR, HIL_GPS, DISTANCE_SENSOR,
HIL_OPTICAL_FLOW, HIL_STATE_QUATERNION) into these objects; the flight controller core sees
nothing else, so it can be driven in-process by tests without sockets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

#: PX4 marks a sensor stale after this many identical samples (``DataValidator``'s
#: ``VALUE_EQUAL_COUNT_DEFAULT``, PX4-Autopilot ``src/modules/sensors/data_validator/``).
STALE_IDENTICAL_SAMPLES = 100


@dataclass(frozen=True)
class GpsFix:
    """One GPS solution (HIL_GPS): position WGS-84, velocity NED, accuracies as PX4 reads
    them (eph/epv in metres)."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    velocity_ned_mps: tuple[float, float, float]
    eph_m: float
    epv_m: float
    fix_type: int
    satellites_used: int


@dataclass(frozen=True)
class RangeReading:
    """One DISTANCE_SENSOR of a downward rangefinder, as PX4 reads it (metres, uORB quality:
    -1 unknown, 0 unusable, 1..100)."""

    distance_m: float
    signal_quality: int
    min_m: float
    max_m: float


@dataclass(frozen=True)
class FlowReading:
    """One HIL_OPTICAL_FLOW as PX4's ``simulator_mavlink`` publishes ``sensor_optical_flow``.

    ``pixel_flow_rad`` is the image's motion over the window about body x and y in the
    sensor's sign convention (a right-handed rotation of the vehicle reads positive, a motion
    along +y negative about x); EKF2 flips it. The window ends at ``time_us``, the arrival on
    the autopilot's clock, which PX4 stamps as the sample time.
    """

    time_us: int
    pixel_flow_rad: tuple[float, float]
    integration_timespan_us: int
    quality: int


@dataclass(frozen=True)
class SensorFrame:
    """One IMU frame (HIL_SENSOR id 0) plus whatever else arrived since the last one.

    Vectors are body FRD. A sensor absent from this frame is ``None``.
    """

    accel_mps2: NDArray[np.float64] | None
    gyro_radps: NDArray[np.float64] | None
    mag_gauss: NDArray[np.float64] | None = None
    baro_pressure_pa: float | None = None
    baro_temperature_degc: float | None = None
    gps: GpsFix | None = None
    range: RangeReading | None = None
    flow: FlowReading | None = None


@dataclass(frozen=True)
class GroundTruth:
    """HIL_STATE_QUATERNION: used only to log the estimator's errors."""

    q: NDArray[np.float64]
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    velocity_ned_mps: NDArray[np.float64]


class SensorMonitor:
    """Tracks one sensor: when it last delivered a new sample, and whether it is stuck."""

    def __init__(self, name: str, timeout_s: float) -> None:
        self.name = name
        self.timeout_us = int(timeout_s * 1e6)
        self.last_time_us: int | None = None
        self._last_value: object = None
        self._repeats = 0

    def sample(self, value: object, time_us: int) -> None:
        key = value.tobytes() if isinstance(value, np.ndarray) else value
        self._repeats = self._repeats + 1 if key == self._last_value else 0
        self._last_value = key
        self.last_time_us = time_us

    def healthy(self, time_us: int) -> bool:
        return (
            self.last_time_us is not None
            and time_us - self.last_time_us <= self.timeout_us
            and self._repeats < STALE_IDENTICAL_SAMPLES
        )

    def fault(self, time_us: int) -> str | None:
        """Why the sensor is unusable (for a status text), or None when healthy."""
        if self.last_time_us is None:
            return "missing"
        if self._repeats >= STALE_IDENTICAL_SAMPLES:
            return "stale"
        if time_us - self.last_time_us > self.timeout_us:
            return "timeout"
        return None
