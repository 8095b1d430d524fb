"""The reference autopilot: a PX4-style multicopter flight controller behind PX4's protocol.

:class:`FlightController` is the in-process core (sensors in, motor commands out, no
sockets); ``python -m rig.autopilots.reference`` runs it as a separate process that
connects to the rig on TCP 4560+i like PX4 SITL and serves ground stations over MAVLink UDP.
"""

from rig.autopilots.reference.flight_controller import CommandResult, Controls, FlightController
from rig.autopilots.reference.params import ParameterError, Parameters
from rig.autopilots.reference.sensors import GpsFix, GroundTruth, SensorFrame

__all__ = [
    "CommandResult",
    "Controls",
    "FlightController",
    "GpsFix",
    "GroundTruth",
    "ParameterError",
    "Parameters",
    "SensorFrame",
]
