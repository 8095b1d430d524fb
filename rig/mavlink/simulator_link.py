"""The simulator side of PX4's simulator MAVLink API: TCP server, lockstep and watchdog.

The rig listens on TCP 127.0.0.1:4560+i and the autopilot connects, as PX4's
``simulator_mavlink`` does (PX4-Autopilot ``src/modules/simulation/simulator_mavlink/``).
Lockstep follows Gazebo-classic's loop, which PX4 SITL (v1.14 and v1.17) was seen to run
with: sensor frames freewheel until the first
HIL_ACTUATOR_CONTROLS has ever arrived; from then on every frame waits for the answer
stamped with its own ``time_usec``. Stale answers (to frames sent while freewheeling) are
consumed on the way, so once lockstep is established the autopilot is never behind.
Freewheeling frames go out at most at real time, as Gazebo streams them: PX4's boot takes
wall time, and a faster stream only stretches it in simulated time, by as much as the
machine happens to be loaded (streamed as fast as the rig could: 0.15–0.6 s, and 1.07 s
once with two test workers beside it; at real time 30–60 ms).

The watchdog turns every way the autopilot can fail into one :class:`AutopilotStalled`
line that says which side stalled: the link closed, the autopilot process exited, or no
answer came within the wall-clock bound. PX4 never reconnects to a simulator, and the
error says so.
"""

from __future__ import annotations

import math
import os
import select
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass

from rig.errors import AutopilotNotConnected, AutopilotStalled
from rig.mavlink.px4_api import Ports, mavlink
from rig.mavlink.sim_messages import (
    ActuatorControls,
    actuator_controls_from_frame,
    decode_actuator_controls,
)

#: What every link failure reminds the user of (PX4's simulator_mavlink spins forever).
PX4_NEVER_RECONNECTS = "PX4 never reconnects to a simulator: start a new PX4 process per run"
#: The rig's own MAVLink identity on the simulator link (Gazebo uses 1/51; PX4 ignores it).
RIG_SYSTEM_ID, RIG_COMPONENT_ID = 1, 51
_RECV_BYTES = 65536
#: With a peer that asks for it (``SimulatorLink.accept``'s ``poll_answers``: the reference
#: autopilot) and while its answers come within this long of the rig starting to wait
#: (wall time), the rig polls for the next one this long before it sleeps in ``select``,
#: yielding the CPU between polls. On a virtual machine a process asleep in ``select``
#: takes 50–150 µs to wake and runs slower for a while after (the reference autopilot
#: polls for its frames for the same reason, ``rig.autopilots.reference.process.
#: FRAME_POLL_S``): the RTL loop at IMU 1 kHz with the reference autopilot ran 1.59–1.79×
#: polling and 1.37–1.59× sleeping, four runs of each taken in turns. Not with PX4: its
#: threads share the cores with the rig, and PX4 + TLM at 250 Hz ran 7.04–7.60× with the
#: rig polling and 7.88–8.66× with it sleeping.
ANSWER_POLL_S = 0.001
#: How long a closed link waits for the autopilot's process to be seen ended, so the error
#: names how it ended: the kernel closes a killed process's sockets before its parent can
#: reap it, and a link can reset a few milliseconds before the exit status exists.
_EXIT_AFTER_CLOSE_S = 2.0


@dataclass(frozen=True)
class LinkTimeouts:
    """Bounds of every wait on the simulator link; none of them is ever infinite.

    ``answer_s`` is wall time for one lockstep answer: generous, because a debugger or a
    loaded machine can pause the autopilot, yet short enough that a hang is reported.
    ``first_answer_sim_s`` bounds the freewheel phase in simulated time, which runs at real
    time. PX4 answered after 30–112 ms when it was measured on an idle machine, but once
    took over 10 s booting beside a Verilator build on the other core: 30 s reports a PX4
    that will never answer without failing one that boots slowly.
    """

    connect_s: float = 60.0
    answer_s: float = 10.0
    first_answer_sim_s: float = 30.0

    def __post_init__(self) -> None:
        for name in ("connect_s", "answer_s", "first_answer_sim_s"):
            value = getattr(self, name)
            if not value > 0:
                raise ValueError(f"LinkTimeouts.{name} must be > 0 s, got {value!r}")


@dataclass
class LinkStats:
    """Counters a run reports: how the lockstep went, what the peer sent, where time went.

    The wall times are disjoint: ``encode_s`` packing MAVLink frames, ``send_s`` in the
    socket's send, ``wait_s`` blocked until the autopilot's bytes arrive (its compute time
    in lockstep), ``decode_s`` parsing and handling what it sent.
    """

    frames_sent: int = 0
    answers: int = 0
    #: Answers not there yet when the rig asked for them: frames in which the autopilot's
    #: compute outlasted the work the rig overlaps with it (the autopilot set the pace),
    #: and the wall time from asking for those to having them.
    late_answers: int = 0
    late_wait_s: float = 0.0
    stale_answers: int = 0
    #: Answers stamped like the one before: PX4 may publish its outputs twice in one step.
    repeated_answers: int = 0
    freewheel_frames: int = 0
    malformed: int = 0
    encode_s: float = 0.0
    send_s: float = 0.0
    wait_s: float = 0.0
    decode_s: float = 0.0


class SimulatorLink:
    """One autopilot connection on ``Ports(instance).simulator_tcp``.

    Parameters
    ----------
    ports
        The SITL instance's port plan.
    timeouts
        Bounds for connecting and for each lockstep answer.
    motors
        The vehicle's rotor count: the outputs of each HIL_ACTUATOR_CONTROLS taken as
        motor commands.
    peer_exit
        Optional callable returning a description of the autopilot's exit (``"exit code
        -9"``) once its process has ended, else ``None``; lets the watchdog tell a dead
        process from a hung one.
    """

    def __init__(
        self,
        ports: Ports,
        timeouts: LinkTimeouts = LinkTimeouts(),
        *,
        motors: int,
        peer_exit: Callable[[], str | None] | None = None,
    ) -> None:
        self.ports = ports
        self.timeouts = timeouts
        self.motors = motors
        self.stats = LinkStats()
        self.mav = mavlink.MAVLink(None, RIG_SYSTEM_ID, RIG_COMPONENT_ID)
        self.mav.robust_parsing = True  # garbage is counted, never an exception mid-run
        #: Interval the autopilot asked for HIL_STATE_QUATERNION (µs), None = not asked (or
        #: stopped).
        self.state_interval_us: int | None = None
        self.peer_heartbeat: mavlink.MAVLink_heartbeat_message | None = None
        self.lockstep = False
        self.peer_exit = peer_exit
        #: Appended to a stall's message: what the autopilot needs to answer every frame.
        self.stall_hint = ""
        self._latest: ActuatorControls | None = None
        self._sent_us = 0  # time_usec of the newest frame sent
        self._first_sent_us: int | None = None  # the clock need not start at 0 (a replay)
        self._first_sent_wall_s = 0.0  # time.monotonic() then
        self._awaited_us: int | None = None  # the frame whose answer is being waited for
        self._last_wait_s = math.inf  # how long the last answer was waited for (wall time)
        self._poll_answers = False  # accept() says
        self._conn: socket.socket | None = None
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._server.bind(("127.0.0.1", ports.simulator_tcp))
        except OSError as error:
            self._server.close()
            raise AutopilotNotConnected(
                f"cannot listen on TCP 127.0.0.1:{ports.simulator_tcp} ({error.strerror}); "
                f"is another rig instance {ports.instance} running?"
            ) from None
        self._server.listen(1)

    @property
    def endpoint(self) -> str:
        return f"TCP 127.0.0.1:{self.ports.simulator_tcp}"

    def accept(
        self,
        waiting_for: str = "the autopilot",
        *,
        answers_every_frame: bool = False,
        poll_answers: bool = False,
    ) -> None:
        """Wait (bounded) for the autopilot to connect, then read what it sends first.

        ``answers_every_frame``: the peer answers every frame from the first (the reference
        autopilot), so the link is in lockstep at once. Freewheeling until a first answer
        (PX4 boots) lets wall time decide how many frames pass unanswered: a run would not
        give the same log twice. ``poll_answers``: the peer runs alone and answers quickly
        (the reference autopilot), so the rig polls for its answers before sleeping
        (:data:`ANSWER_POLL_S`).
        """
        deadline = time.monotonic() + self.timeouts.connect_s
        while self._conn is None:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AutopilotNotConnected(
                    f"no autopilot connected to {self.endpoint} within "
                    f"{self.timeouts.connect_s:g} s; start {waiting_for}"
                )
            exit_reason = self._peer_exit_reason()
            if exit_reason is not None:
                raise AutopilotNotConnected(
                    f"the autopilot process ended before connecting to {self.endpoint} "
                    f"({exit_reason})"
                )
            ready, _, _ = select.select([self._server], [], [], min(remaining, 0.1))
            if ready:
                conn, _ = self._server.accept()
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self._conn = conn
        self._server.close()  # one autopilot per link: PX4 does not reconnect anyway
        self.lockstep = answers_every_frame
        self._poll_answers = poll_answers

    def send(self, *messages: mavlink.MAVLink_message | bytes) -> None:
        """Write messages to the autopilot as MAVLink 2 frames (``bytes``: one packed
        already, as :func:`rig.mavlink.sim_messages.hil_sensor_frame` makes it)."""
        started = time.perf_counter()
        payload = b"".join(
            message if isinstance(message, bytes) else message.pack(self.mav)
            for message in messages
        )
        packed = time.perf_counter()
        self.stats.encode_s += packed - started
        try:
            self._connection().sendall(payload)
        except OSError as error:
            raise AutopilotStalled(
                f"the autopilot closed the simulator link ({self.endpoint}: {error.strerror})"
                f"{self._exit_note()}; {PX4_NEVER_RECONNECTS}"
            ) from None
        self.stats.send_s += time.perf_counter() - packed

    def exchange(
        self, time_us: int, messages: list[mavlink.MAVLink_message | bytes]
    ) -> ActuatorControls | None:
        """Send one sensor frame and return the motor commands for the next step.

        :meth:`send_frame` then :meth:`answer`; the rig's loop calls the two itself, so it
        can do what does not need the answer while the autopilot computes it.
        """
        self.send_frame(time_us, messages)
        return self.answer(time_us)

    def send_frame(self, time_us: int, messages: list[mavlink.MAVLink_message | bytes]) -> None:
        """Send the sensor frame stamped ``time_us`` (its HIL_SENSOR and what goes with it)."""
        self.send(*messages)
        self._sent_us = time_us
        if self._first_sent_us is None:
            self._first_sent_us = time_us
            self._first_sent_wall_s = time.monotonic()
        self.stats.frames_sent += 1

    def answer(self, time_us: int) -> ActuatorControls | None:
        """The motor commands after the frame ``time_us`` was sent.

        Freewheeling: the latest actuator message received so far (None before the first).
        In lockstep: blocks until the answer stamped ``time_us`` arrives.
        """
        if not self.lockstep:
            self.stats.freewheel_frames += 1
            self._receive_until_due(time_us)
            if self._latest is not None:
                self.lockstep = True
                self._wait_for_answer(time_us)
            elif time_us - (self._first_sent_us or 0) > self.timeouts.first_answer_sim_s * 1e6:
                raise AutopilotStalled(
                    f"the autopilot connected but sent no HIL_ACTUATOR_CONTROLS in "
                    f"{self.timeouts.first_answer_sim_s:g} s of simulated time "
                    f"({self.stats.malformed} malformed messages received); check that it "
                    "runs the simulator_mavlink module with lockstep"
                )
            return self._latest
        self._wait_for_answer(time_us)
        return self._latest

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
        self._server.close()

    def __enter__(self) -> SimulatorLink:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _connection(self) -> socket.socket:
        if self._conn is None:
            raise AutopilotNotConnected(f"no autopilot connected to {self.endpoint} yet")
        return self._conn

    def _receive_until_due(self, time_us: int) -> None:
        """Freewheeling: read what the autopilot sends until ``time_us`` is due in real
        time, counted from the first frame's send, or until its first answer."""
        due_s = self._first_sent_wall_s + (time_us - (self._first_sent_us or 0)) / 1e6
        while True:
            self._receive(max(0.0, due_s - time.monotonic()))
            if self._latest is not None or time.monotonic() >= due_s:
                return

    def _wait_for_answer(self, time_us: int) -> None:
        deadline = time.monotonic() + self.timeouts.answer_s
        self._awaited_us = time_us
        waiting = time.perf_counter()
        self._receive(0.0)  # what has arrived: the answer, unless the autopilot is late
        late = self._latest is None or self._latest.time_us < time_us
        if late and self._poll_answers and self._last_wait_s < ANSWER_POLL_S:
            self._poll(waiting + ANSWER_POLL_S)
        while self._latest is None or self._latest.time_us < time_us:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                last = "none" if self._latest is None else f"t={self._latest.time_us / 1e6:.6f} s"
                raise AutopilotStalled(
                    f"the autopilot stalled: no HIL_ACTUATOR_CONTROLS for the frame at "
                    f"t={time_us / 1e6:.6f} s within {self.timeouts.answer_s:g} s of wall "
                    f"time (the rig sent the frame and is waiting; last answer {last}; "
                    f"{self.stats.malformed} malformed messages){self._exit_note()}"
                    f"{self.stall_hint}"
                )
            self._receive(min(remaining, 0.25))
        self._awaited_us = None
        self._last_wait_s = time.perf_counter() - waiting
        self.stats.answers += 1
        if late:
            self.stats.late_answers += 1
            self.stats.late_wait_s += self._last_wait_s

    def _poll(self, until_s: float) -> None:
        """Poll for the autopilot's bytes until they are there or ``until_s`` (a
        ``perf_counter`` time) has passed, yielding the CPU between polls."""
        conn = self._connection()
        started = time.perf_counter()
        while not select.select([conn], [], [], 0)[0] and time.perf_counter() < until_s:
            os.sched_yield()
        self.stats.wait_s += time.perf_counter() - started

    def _receive(self, timeout_s: float) -> None:
        """Read what is there (waiting at most ``timeout_s``) and handle each message."""
        conn = self._connection()
        started = time.perf_counter()
        ready, _, _ = select.select([conn], [], [], timeout_s)
        if not ready:
            self.stats.wait_s += time.perf_counter() - started
            exit_reason = self._peer_exit_reason()
            if exit_reason is not None:
                raise AutopilotStalled(
                    f"the autopilot process ended ({exit_reason}) while the rig waited for "
                    f"its answer on {self.endpoint}"
                )
            return
        try:
            data = conn.recv(_RECV_BYTES)
        except ConnectionError as error:
            data, reason = b"", error.strerror
        else:
            reason = "end of stream"
        received = time.perf_counter()
        self.stats.wait_s += received - started
        if not data:
            raise AutopilotStalled(
                f"the autopilot closed the simulator link ({self.endpoint}: {reason})"
                f"{self._exit_note()}; {PX4_NEVER_RECONNECTS}"
            )
        controls = None
        if self.mav.buf_len() == 0:
            controls = actuator_controls_from_frame(data, self.motors)
        if controls is not None:
            self._take_controls(controls)
        else:
            for message in self.mav.parse_buffer(data) or ():
                self._handle(message)
        self.stats.decode_s += time.perf_counter() - received

    def _handle(self, message: mavlink.MAVLink_message) -> None:
        kind = message.get_type()
        if kind == "HIL_ACTUATOR_CONTROLS":
            self._take_controls(decode_actuator_controls(message, self.motors))
        elif kind == "HEARTBEAT":
            self.peer_heartbeat = message
        elif kind == "COMMAND_LONG":
            is_interval = message.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
            if is_interval and int(message.param1) == mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION:
                # MAVLink: -1 stops the stream; 0 asks for a default rate, which a
                # simulator has none of (PX4 asks for 5000 µs)
                interval_us = int(message.param2)
                self.state_interval_us = interval_us if interval_us > 0 else None
        elif kind == "BAD_DATA":
            self.stats.malformed += 1

    def _take_controls(self, controls: ActuatorControls) -> None:
        previous_us = -1 if self._latest is None else self._latest.time_us
        if controls.time_us == previous_us:
            self.stats.repeated_answers += 1
            return
        if not previous_us < controls.time_us <= self._sent_us:
            self.stats.malformed += 1  # backwards or from the future: answers no frame
            return
        if self._awaited_us is not None and controls.time_us < self._awaited_us:
            self.stats.stale_answers += 1
        self._latest = controls

    def _exit_note(self) -> str:
        """`` (autopilot process …)`` when the peer's process ends within
        :data:`_EXIT_AFTER_CLOSE_S` of the link closing, else nothing."""
        if self.peer_exit is None:
            return ""
        deadline = time.monotonic() + _EXIT_AFTER_CLOSE_S
        while (exit_reason := self.peer_exit()) is None and time.monotonic() < deadline:
            time.sleep(0.02)
        return f" (autopilot process {exit_reason})" if exit_reason else ""

    def _peer_exit_reason(self) -> str | None:
        return None if self.peer_exit is None else self.peer_exit()
