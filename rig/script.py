"""The scenario's command script in simulated time: what to send to the autopilot, when.

Turns each :class:`rig.scenario.Command` into a ground-station conversation
(:mod:`rig.ground`) at its time, and keeps the offboard setpoint streams alive the way
MAVSDK does (PX4 leaves offboard when setpoints stop): a ``goto`` re-sends its position
setpoint every 0.1 s, a ``pitch_sweep`` streams attitude setpoints at ``rate_hz``. Any
mode command (takeoff, land, mission, another stream) ends the running stream.

With ``barrier=True`` (the reference autopilot) every setpoint travels inside an
acknowledged conversation, so it acts at a known frame; with PX4 the stream is sent
without waiting, as PX4 acts only when its clock advances.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

from rig.ground import OFFBOARD_KEEPALIVE_S, Conversation, GroundLink, sweep_pitch_rad
from rig.px4_sim_api import mavlink
from rig.scenario import Command


@dataclass(frozen=True)
class Action:
    """One thing to do at this frame: a conversation, or setpoints sent without waiting."""

    name: str
    conversation: Conversation | None = None
    unacknowledged: tuple[mavlink.MAVLink_message, ...] = ()
    #: False for a stream's keep-alive repeats: only its first setpoint is a log event.
    logged: bool = True


@dataclass
class _Stream:
    command: Command
    started_s: float
    next_s: float
    period_s: float
    announced: bool = False


class CommandScript:
    """Walks the scenario's commands in time order and yields the actions due."""

    def __init__(self, commands: tuple[Command, ...], ground: GroundLink, *, barrier: bool) -> None:
        self.ground = ground
        self.barrier = barrier
        self._commands = list(commands)
        self._next = 0
        self._stream: _Stream | None = None

    def due(self, time_s: float) -> Iterator[Action]:
        while self._next < len(self._commands) and self._commands[self._next].at_s <= time_s + 1e-9:
            command = self._commands[self._next]
            self._next += 1
            yield from self._start(command, time_s)
        stream = self._stream
        if stream is not None and time_s + 1e-9 >= stream.next_s:
            action = self._stream_action(stream, time_s)
            if action is not None:
                yield action

    def _start(self, command: Command, time_s: float) -> Iterator[Action]:
        g, p, name = self.ground, command.params, f"{command.action} at t={command.at_s:g} s"
        self._stream = None  # every command takes over from a running setpoint stream
        if command.action in ("goto", "pitch_sweep"):
            rate_hz = p.get("rate_hz", 50.0) if command.action == "pitch_sweep" else None
            period = 1.0 / rate_hz if rate_hz else OFFBOARD_KEEPALIVE_S
            self._stream = _Stream(command, time_s, time_s, period)
            return
        conversations = {
            "arm": lambda: g.arm(True),
            "disarm": lambda: g.arm(False),
            "takeoff": lambda: g.takeoff(p["altitude_m"]),
            "land": g.land,
            "mission": lambda: g.mission(p["waypoints_ned_m"]),
            "motor_test": lambda: g.motor_test(p["motor"], p["throttle"], p["duration_s"]),
            "set_param": lambda: g.set_param(p["name"], p["value"]),
        }
        yield Action(name, conversations[command.action]())

    def _stream_action(self, stream: _Stream, time_s: float) -> Action | None:
        command, p = stream.command, stream.command.params
        stream.next_s += stream.period_s
        if command.action == "goto":
            setpoint = self.ground.position_setpoint(p["position_ned_m"], p.get("yaw_deg"), time_s)
        else:
            elapsed = time_s - stream.started_s
            if elapsed > p["duration_s"]:
                self._stream = None
                return None
            pitch = sweep_pitch_rad(
                elapsed, p["duration_s"], math.radians(p["amplitude_deg"]),
                p["f_min_radps"], p["f_max_radps"],
            )  # fmt: skip
            setpoint = self.ground.attitude_setpoint(0.0, pitch, 0.0, p["thrust"], time_s)
        name = f"{command.action} at t={command.at_s:g} s"
        first = not stream.announced
        stream.announced = True
        if self.barrier or first:
            return Action(name, self.ground.offboard([setpoint], name), logged=first)
        return Action(name, unacknowledged=(setpoint,), logged=False)
