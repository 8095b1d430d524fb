"""What to replay and how: the options of ``rig replay`` and its error."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from rig.autopilots import Autopilot
from rig.errors import RigError
from rig.scenarios.scenario import SensorLayer


class Drive(StrEnum):
    """Which of the log's set-points the reference autopilot flies (``--drive``)."""

    #: Offboard velocity set-points (``vehicle_local_position_setpoint``): the whole flight.
    VELOCITY = "velocity"
    #: Attitude and thrust (``vehicle_attitude_setpoint``), inside ``--window``.
    ATTITUDE = "attitude"
    #: Body rates and thrust (``vehicle_rates_setpoint``), inside ``--window``.
    RATES = "rates"


class ReplayError(RigError):
    """A flight log or replay option that cannot be flown: names the file, field and value."""


@dataclass(frozen=True)
class ReplayOptions:
    """What to replay and how (times are the log's boot seconds)."""

    drive: Drive = Drive.VELOCITY
    window_s: tuple[float, float] | None = None
    start_s: float | None = None  # None: the log's first timestamp
    end_s: float | None = None  # None: the log's last timestamp
    vehicle: str | None = None  # None: from SYS_AUTOSTART
    seed: int = 0
    sensor_layer: SensorLayer = SensorLayer.TLM
    imu_hz: int | None = None  # None: Rates' default (1000 Hz); with PX4 see PX4_IMU_HZ
    autopilot: Autopilot = Autopilot.REFERENCE
    px4_dir: Path | None = None  # PX4's build (--px4); None: $PX4_DIR
