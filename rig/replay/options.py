"""What to replay and how: the options of ``rig replay`` and its error."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rig.autopilots import Autopilot
from rig.errors import RigError
from rig.scenarios.scenario import SensorLayer

DRIVES = ("velocity", "attitude", "rates")


class ReplayError(RigError):
    """A flight log or replay option that cannot be flown: names the file, field and value."""


@dataclass(frozen=True)
class ReplayOptions:
    """What to replay and how (times are the log's boot seconds)."""

    drive: str = "velocity"
    window_s: tuple[float, float] | None = None
    start_s: float | None = None  # None: the log's first timestamp
    end_s: float | None = None  # None: the log's last timestamp
    vehicle: str | None = None  # None: from SYS_AUTOSTART
    seed: int = 0
    sensor_layer: SensorLayer = SensorLayer.TLM
    imu_hz: int | None = None  # None: Rates' default (1000 Hz); with PX4 see PX4_IMU_HZ
    autopilot: Autopilot = Autopilot.REFERENCE
    px4_dir: Path | None = None  # PX4's build (--px4); None: $PX4_DIR
