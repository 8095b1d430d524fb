"""``rig replay REAL.ulg``: fly a real PX4 flight's own commands through the rig.

:func:`plan_replay` reads the log and configures the run from it, without flying: the
vehicle from ``SYS_AUTOSTART`` (``--vehicle`` wins), the battery's cell count, every
parameter the reference autopilot knows, the start heading, the home position, the real
arm/disarm times and the setpoint tracks of the chosen drive, the motor outputs' PWM
range (so the armed motors idle at command 0 as the real ones did) and the battery's
resting voltage at the start (the pack is rarely full, and the ESC speed follows it).
:func:`run_replay` flies the plan and leaves ``rig.ulg``, ``autopilot.ulg``, the derived
``vehicle.toml`` and ``replay.json`` (what was applied, skipped and assumed) in the run folder.

The autopilot's clock starts at the real log's first timestamp, so the replayed logs share
the real log's time axis (ULog boot seconds) and one credibility plan scores both.

Drives (the reference autopilot's matching loop takes the log's own setpoints):

- ``velocity``: ``vehicle_local_position_setpoint`` vx, vy, vz (+ yaw when finite) as
  offboard velocity setpoints; it flies the whole flight, take-off and landing included.
- ``attitude``: ``vehicle_attitude_setpoint`` q_d and thrust, inside ``--window``.
- ``rates``: ``vehicle_rates_setpoint`` body rates and thrust, inside ``--window``.

Attitude and rates are open loop on position, so the velocity drive flies the vehicle to
the window and takes over again after it.

``--autopilot px4`` flies PX4 SITL instead, with the firmware's own parameters from the log
(:func:`rig.autopilots.px4.sitl_parameters` decides which ones SITL takes) and as the pilot
flew it: the log's sticks (``manual_control_setpoint``) as MANUAL_CONTROL, its arm, mode
switches and disarm at their times (``vehicle_status``), its mission uploaded as it was
flown (``navigator_mission_item``) and, in Offboard, its velocity setpoints. PX4 boots
PX4_BOOT_S before the log's start, so it is ready when the log arms.
"""

from rig.replay.options import Drive, ReplayError, ReplayOptions
from rig.replay.plan import Replay, plan_replay
from rig.replay.run import run_replay

__all__ = ["Drive", "Replay", "ReplayError", "ReplayOptions", "plan_replay", "run_replay"]
