"""PX4's simulator MAVLink API and SITL port plan: the facts both sides of the link share.

One place for what PX4's ``simulator_mavlink`` module expects (PX4-Autopilot
``src/modules/simulation/simulator_mavlink/SimulatorMavlink.cpp``, and what PX4 SITL v1.14
and v1.17 were seen to do), so the rig, the reference autopilot and the tests cannot
drift apart. MAVLink 2 is required (``HIL_SENSOR.id`` is an extension field).
"""

from __future__ import annotations

import enum
import os
import socket
from dataclasses import dataclass

# pymavlink picks MAVLink 1 or 2 at import time from this variable; PX4 needs version 2.
os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import common as mavlink  # after MAVLINK20 is set

__all__ = ["MOTOR_ORDER", "ActuatorMode", "HilSensorFields", "Ports", "free_instance", "mavlink"]


class HilSensorFields(enum.IntFlag):
    """``HIL_SENSOR.fields_updated``: a sensor counts only when all of its bits are set."""

    ACCEL = 0b111  # xacc, yacc, zacc (m/s², specific force, FRD)
    GYRO = 0b111 << 3  # xgyro, ygyro, zgyro (rad/s, FRD)
    MAG = 0b111 << 6  # xmag, ymag, zmag (gauss, FRD)
    BARO = (1 << 9) | (1 << 11) | (1 << 12)  # abs_pressure (hPa), pressure_alt, temperature (°C)
    DIFF_PRESSURE = 1 << 10  # diff_pressure (hPa)


class ActuatorMode(enum.IntFlag):
    """``HIL_ACTUATOR_CONTROLS.mode`` bits PX4 sets (MAV_MODE_FLAG values)."""

    CUSTOM_MODE_ENABLED = 1
    SAFETY_ARMED = 128


# The flags as plain ints, for the code that encodes or decodes them every frame (the rig's
# messages, the reference autopilot): an IntFlag operation costs about a microsecond.
ACCEL_FIELDS, GYRO_FIELDS = int(HilSensorFields.ACCEL), int(HilSensorFields.GYRO)
MAG_FIELDS, BARO_FIELDS = int(HilSensorFields.MAG), int(HilSensorFields.BARO)
CUSTOM_MODE_ENABLED = int(ActuatorMode.CUSTOM_MODE_ENABLED)
SAFETY_ARMED = int(ActuatorMode.SAFETY_ARMED)


#: ``HIL_ACTUATOR_CONTROLS.flags`` bit 0: the autopilot runs in lockstep with the simulator.
LOCKSTEP_FLAG = 1

#: Quad-X output channels as PX4 numbers them: (position, spin seen from above).
MOTOR_ORDER = (
    ("front-right", "CCW"),
    ("rear-left", "CCW"),
    ("front-left", "CW"),
    ("rear-right", "CW"),
)

#: PX4 SITL's default home, where its world magnetic model check passes.
DEFAULT_HOME_LAT_DEG = 47.397742
DEFAULT_HOME_LON_DEG = 8.545594
DEFAULT_HOME_ALT_AMSL_M = 488.0


@dataclass(frozen=True)
class Ports:
    """Loopback ports of one SITL instance ``i``, as PX4 assigns them."""

    instance: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.instance < 100:
            raise ValueError(f"instance must be in 0..99, got {self.instance}")

    @property
    def simulator_tcp(self) -> int:
        """The rig listens here; the autopilot connects (PX4 ``simulator_mavlink -c``)."""
        return 4560 + self.instance

    @property
    def gcs_local_udp(self) -> int:
        """The autopilot binds this for the ground-station link."""
        return 18570 + self.instance

    gcs_remote_udp: int = 14550  # QGroundControl / MAVProxy listen here

    @property
    def api_local_udp(self) -> int:
        """The autopilot binds this for the offboard/API link (MAVSDK, scripts)."""
        return 14580 + self.instance

    @property
    def api_remote_udp(self) -> int:
        """MAVSDK and scripts listen here; the rig never binds it."""
        return 14540 + self.instance

    @property
    def onboard_local_udp(self) -> int:
        """The autopilot binds this for PX4's onboard payload link (``px4-rc.mavlink``)."""
        return 14280 + self.instance

    @property
    def onboard_remote_udp(self) -> int:
        """The rig binds this: its scenario commands go out as a companion computer's do,
        so MAVSDK (14540+i) and QGroundControl (14550) stay free for the user."""
        return 14030 + self.instance

    @property
    def system_id(self) -> int:
        return self.instance + 1


def free_instance(first: int, count: int, index: int = 0) -> int:
    """The first instance from ``first + index % count`` on (wrapping within the range)
    whose ports are all free right now, the rig's and the autopilot's, so concurrent runs
    given consecutive indices start on different instances, and a port held by anyone
    else (an autopilot still shutting down, another program) is skipped. Raises
    ``OSError`` when every instance in the range is busy."""
    for step in range(count):
        instance = first + (index + step) % count
        ports = Ports(instance)
        udp_ports = (ports.onboard_remote_udp, ports.gcs_local_udp, ports.api_local_udp,
                     ports.onboard_local_udp)  # fmt: skip
        sockets = [socket.socket(), *(socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                                      for _ in udp_ports)]  # fmt: skip
        try:
            for sock, port in zip(sockets, (ports.simulator_tcp, *udp_ports), strict=True):
                sock.bind(("127.0.0.1", port))
        except OSError:
            continue
        finally:
            for sock in sockets:
                sock.close()
        return instance
    raise OSError(f"no free SITL instance in {first}..{first + count - 1}")
