"""The scenario's command script in simulated time: what to send to the autopilot, when.

Turns each command of :mod:`rig.scenarios.scenario` into a ground-station conversation
(:mod:`rig.mavlink.ground_link`) at its time, and keeps the offboard setpoint streams alive
the way MAVSDK does (PX4 leaves offboard when setpoints stop): a ``goto`` re-sends its
position setpoint every 0.1 s, a ``pitch_sweep`` streams attitude setpoints at ``rate_hz``,
a ``track`` sends a :class:`~rig.scenarios.scenario.SetpointTrack`'s recorded setpoints at
their times and holds the last one (re-sent every 0.1 s) between them. A mode command
(takeoff, land, mission, mode, motor test, another stream) ends the running stream; arm,
disarm, set_param, a mission upload and a home do not change the mode, so the stream goes on as
MAVSDK's does (a replay arms and disarms mid-stream).

A ``manual`` track (or a file's ``sticks``, held) is a pilot's sticks, played as
QGroundControl plays a joystick: MANUAL_CONTROL every 20 ms (PX4 takes the sticks as lost
after COM_RC_LOSS_T, 0.5 s), the track interpolated linearly between its samples (a real
log holds them at 5 Hz), and the ground station's HEARTBEAT every second. It runs beside
the setpoint streams, and no mode command ends it: the pilot holds the sticks in every mode.

With ``barrier=True`` (the reference autopilot) every setpoint travels inside an
acknowledged conversation, so it acts at a known frame; with PX4 the stream is sent
without waiting, as PX4 acts only when its clock advances.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import assert_never

from rig.mavlink.ground_link import OFFBOARD_KEEPALIVE_S, Conversation, GroundLink, sweep_pitch_rad
from rig.mavlink.px4_api import mavlink
from rig.scenarios.scenario import (
    Arm,
    Disarm,
    Goto,
    Hold,
    Land,
    Mission,
    MotorTest,
    PitchSweep,
    ScriptCommand,
    SetHome,
    SetMode,
    SetParam,
    SetpointTrack,
    Sticks,
    Takeoff,
    Track,
    UploadMission,
)

#: A pilot's sticks are sent this often (µs of simulated time): well inside PX4's 0.5 s.
STICKS_PERIOD_US = 20_000
#: The ground station's HEARTBEAT beside the sticks (µs).
HEARTBEAT_PERIOD_US = 1_000_000


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
    command: Goto | PitchSweep | Track
    started_us: int
    next_us: int
    period_us: int
    announced: bool = False
    sample: int = 0  # a track's latest sample due


def _next_on_grid(due_us: int, period_us: int, time_us: int) -> int:
    """The first time after ``time_us`` on the grid ``due_us`` + k·``period_us``."""
    return due_us + ((time_us - due_us) // period_us + 1) * period_us


def _us(time_s: float) -> int:
    """A file's time (s) on the frames' whole-µs grid."""
    return round(time_s * 1e6)


#: The keep-alive period of a setpoint stream (µs).
_KEEPALIVE_US = _us(OFFBOARD_KEEPALIVE_S)


#: Commands that leave the flight mode, and so a running setpoint stream, as they are.
_KEEP_STREAM = frozenset({"arm", "disarm", "set_param", "upload_mission", "set_home"})


@dataclass
class _Sticks:
    """A pilot's sticks being played (a ``manual`` track): the next sends and the sample."""

    track: SetpointTrack
    next_us: int
    heartbeat_us: int
    sample: int = 0

    def at(self, time_s: float) -> tuple[float, ...]:
        """The sticks at ``time_s``: linear between the samples around it, the first one
        before and the last one after them."""
        times, values = self.track.times_s, self.track.values
        while self.sample + 1 < len(times) and times[self.sample + 1] <= time_s:
            self.sample += 1
        here = values[self.sample]
        if self.sample + 1 == len(times) or time_s <= times[self.sample]:
            return here
        t0, t1, there = times[self.sample], times[self.sample + 1], values[self.sample + 1]
        share = (time_s - t0) / (t1 - t0)
        return tuple(a + (b - a) * share for a, b in zip(here, there, strict=True))


class CommandScript:
    """Walks the scenario's commands in time order and yields the actions due.

    Times are run microseconds, whole numbers like every clock of the rig (a float sum of
    stream periods would drift over a long run); setpoints are stamped ``clock_start_s``
    later (the autopilot's boot clock, which a replay starts at the real log's first
    timestamp).
    """

    def __init__(
        self,
        commands: tuple[ScriptCommand, ...],
        ground: GroundLink,
        *,
        barrier: bool,
        clock_start_s: float = 0.0,
    ) -> None:
        self.ground = ground
        self.barrier = barrier
        self.clock_start_s = clock_start_s
        self._commands = list(commands)
        self._due_us = [_us(command.at_s) for command in self._commands]
        self._next = 0
        self._stream: _Stream | None = None
        self._sticks: _Sticks | None = None

    def due(self, time_us: int) -> Iterator[Action]:
        """The actions due at run time ``time_us``."""
        while self._next < len(self._commands) and self._due_us[self._next] <= time_us:
            command = self._commands[self._next]
            self._next += 1
            yield from self._start(command, time_us)
        stream = self._stream
        if stream is not None and time_us >= stream.next_us:
            action = self._stream_action(stream, time_us)
            if action is not None:
                yield action
        sticks = self._sticks
        if sticks is not None and time_us >= sticks.next_us:
            yield self._sticks_action(sticks, time_us)

    def _start(self, command: ScriptCommand, time_us: int) -> Iterator[Action]:
        g, name = self.ground, f"{command.action} at t={command.at_s:g} s"
        if isinstance(command, Track) and command.track.kind == "manual":
            self._sticks = _Sticks(command.track, time_us, time_us)
            return
        if isinstance(command, Sticks):  # held until the next: a one-sample manual track
            held = (command.roll, command.pitch, command.yaw, command.throttle)
            track = SetpointTrack("manual", (command.at_s,), (held,))
            heartbeat_us = time_us if self._sticks is None else self._sticks.heartbeat_us
            self._sticks = _Sticks(track, time_us, heartbeat_us)
            return
        if command.action not in _KEEP_STREAM:
            self._stream = None  # a mode command takes over from a running setpoint stream
        if isinstance(command, Goto | PitchSweep | Track):
            period = _us(1.0 / command.rate_hz) if isinstance(command, PitchSweep) else None
            self._stream = _Stream(command, time_us, time_us, period or _KEEPALIVE_US)
            return
        match command:
            # PX4 (not the barrier) is asked again until its pre-flight checks pass
            case Arm():
                conversation = g.arm(True) if self.barrier else g.arm_when_ready()
            # a replay's disarm follows the real flight's and may find this one still flying
            case Disarm():
                conversation = g.attempt(g.arm(False)) if command.may_refuse else g.arm(False)
            case Takeoff():
                conversation = g.takeoff(command.altitude_m)
            case Land():
                conversation = g.land()
            case Hold():
                conversation = g.hold()
            case SetMode():
                conversation = g.attempt(g.set_mode(command.nav_state))
            case Mission():
                conversation = g.mission(command.waypoints_ned_m)
            case UploadMission():
                conversation = g.upload_mission(command.items)
            # a replay's home, where the real PX4 moved it: a refusal (COM_HOME_EN 0 in the
            # log's parameters) leaves PX4's own, and the flight goes on as the pilot's did
            case SetHome():
                conversation = g.attempt(g.set_home(command.home))
            case MotorTest():
                conversation = g.motor_test(command.motor, command.throttle, command.duration_s)
            case SetParam():
                conversation = g.set_param(command.name, command.value)
            case _:
                assert_never(command)
        yield Action(name, conversation)

    def _stream_action(self, stream: _Stream, time_us: int) -> Action | None:
        command = stream.command
        stream.next_us += stream.period_us
        stamp_s = self.clock_start_s + time_us / 1e6
        if isinstance(command, Goto):
            setpoint = self.ground.position_setpoint(
                command.position_ned_m, command.yaw_deg, stamp_s
            )
        elif isinstance(command, Track):
            setpoint = self._track_setpoint(stream, command.track, time_us, stamp_s)
        else:
            elapsed = (time_us - stream.started_us) / 1e6
            if elapsed > command.duration_s:
                self._stream = None
                return None
            pitch = sweep_pitch_rad(
                elapsed, command.duration_s, math.radians(command.amplitude_deg),
                command.f_min_radps, command.f_max_radps,
            )  # fmt: skip
            setpoint = self.ground.attitude_setpoint(0.0, pitch, 0.0, command.thrust, stamp_s)
        name = f"{command.action} at t={command.at_s:g} s"
        first = not stream.announced
        stream.announced = True
        if self.barrier or first:
            return Action(name, self.ground.offboard([setpoint], name), logged=first)
        return Action(name, unacknowledged=(setpoint,), logged=False)

    def _sticks_action(self, sticks: _Sticks, time_us: int) -> Action:
        """The sticks now as MANUAL_CONTROL, with the ground station's HEARTBEAT when due;
        never waited for (PX4's sticks are a stream, not a conversation)."""
        sticks.next_us = _next_on_grid(sticks.next_us, STICKS_PERIOD_US, time_us)
        roll, pitch, yaw, throttle = sticks.at(time_us / 1e6)
        messages = [self.ground.manual_control(roll, pitch, yaw, throttle)]
        if time_us >= sticks.heartbeat_us:
            sticks.heartbeat_us = _next_on_grid(sticks.heartbeat_us, HEARTBEAT_PERIOD_US, time_us)
            messages.append(self.ground.heartbeat())
        return Action("sticks", unacknowledged=tuple(messages), logged=False)

    def _track_setpoint(
        self, stream: _Stream, track: SetpointTrack, time_us: int, stamp_s: float
    ) -> mavlink.MAVLink_message:
        """The track's latest sample at ``time_us`` as a message; schedules the next send: the
        next sample's time, or the keep-alive if that comes first."""
        times = track.times_s
        while stream.sample + 1 < len(times) and _us(times[stream.sample + 1]) <= time_us:
            stream.sample += 1
        keepalive_us = time_us + _KEEPALIVE_US
        if stream.sample + 1 < len(times):
            stream.next_us = min(_us(times[stream.sample + 1]), keepalive_us)
        else:
            stream.next_us = keepalive_us
        value, ground = track.values[stream.sample], self.ground
        if track.kind == "velocity":
            yaw = value[3] if math.isfinite(value[3]) else None
            return ground.velocity_setpoint(value[:3], yaw, stamp_s)
        if track.kind == "attitude":
            return ground.quaternion_setpoint(value[:4], value[4], stamp_s)
        return ground.rates_setpoint(value[:3], value[3], stamp_s)
