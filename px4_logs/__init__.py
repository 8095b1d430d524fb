"""Reading PX4 flight logs for every tool of the project: the guarded ULog reader, older
PX4 layouts, a topic's value at a time, arming and hover spans, the motor outputs of every
PX4 output driver, the ESCs' measured rotor speeds.

It sits under both ``credibility`` and ``rig`` and imports neither.
"""

from px4_logs.errors import LogError
from px4_logs.flight_log import ARMING_STATE_ARMED, FlightLog
from px4_logs.outputs import MotorOutputs, OutputProtocol, motor_outputs
from px4_logs.ulog import firmware_name, read_ulog

__all__ = [
    "ARMING_STATE_ARMED",
    "FlightLog",
    "LogError",
    "MotorOutputs",
    "OutputProtocol",
    "firmware_name",
    "motor_outputs",
    "read_ulog",
]
