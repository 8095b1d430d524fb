"""Reading PX4 flight logs for every tool of the project: the guarded ULog reader, older
PX4 layouts, a topic's value at a time, arming and hover spans, the motor outputs.

It sits under both ``credibility`` and ``rig`` and imports neither.
"""

from px4_logs.errors import LogError
from px4_logs.flight_log import FlightLog
from px4_logs.outputs import motor_pwm_range
from px4_logs.ulog import firmware_name, read_ulog

__all__ = ["FlightLog", "LogError", "firmware_name", "motor_pwm_range", "read_ulog"]
