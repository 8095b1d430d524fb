"""The scenario's ground station: MAVLink commands on the autopilot's onboard link.

The rig plays the part a companion computer plays against PX4 SITL: it binds UDP
127.0.0.1:14030+i and talks to the autopilot's onboard payload link at 14280+i (``Ports``),
so a user's MAVSDK (14540+i) and ground station (14550) connect beside it. Each scenario
action is a *conversation*: a generator that yields :class:`Expect` (messages to send, and
which answer completes the step) and finally returns a one-line result. Two drivers run the
same conversation:

- :meth:`GroundLink.converse_now` (reference autopilot): the autopilot handles ground
  messages as they arrive, between sensor frames, so the rig waits here (bounded in wall
  time) before it sends the next HIL_SENSOR. The command then acts at a known frame,
  which makes a run deterministic.
- :meth:`GroundLink.poll` (PX4 SITL): PX4 acts only when its lockstep clock advances, so
  the rig keeps stepping and polls each frame, bounded in simulated time.

Unacknowledged setpoint streams (offboard position, attitude) are made deterministic the
same way: with the reference autopilot each setpoint is followed by an acknowledged
DO_SET_MODE(OFFBOARD), whose ACK proves the setpoint before it was handled (one UDP
socket is read in order).

PX4 facts used here (PX4-Autopilot ``src/modules/commander/px4_custom_mode.h``,
``src/modules/mavlink/mavlink_receiver.cpp``, MAVLink ``common.xml``): custom main mode
OFFBOARD = 6; NAV_TAKEOFF with a NaN altitude climbs MIS_TAKEOFF_ALT above home;
DO_MOTOR_TEST takes a 1-based motor instance and a percentage; MANUAL_CONTROL carries
pitch in x, roll in y and yaw in r (±1000) and the throttle in z (0..1000, PX4 reads
z/500 − 1); a ground station is one that sends HEARTBEAT of type GCS.
"""

from __future__ import annotations

import math
import select
import socket
import struct
import time
from collections.abc import Callable, Generator, Iterable, Sequence
from dataclasses import dataclass, field

from quad_model.environment import GeoPoint
from quad_model.frames import ned_to_geodetic, quat_from_euler
from rig.errors import GroundLinkError
from rig.mavlink.px4_api import Ports, mavlink

#: The rig's identity as a ground station (MAVSDK's default system id for a GCS is 245).
GCS_SYSTEM_ID, GCS_COMPONENT_ID = 245, mavlink.MAV_COMP_ID_MISSIONPLANNER
#: PX4 custom main mode OFFBOARD (px4_custom_mode.h).
PX4_MAIN_MODE_OFFBOARD = 6
#: PX4's Hold: main mode AUTO, sub mode LOITER (px4_custom_mode.h).
PX4_MAIN_MODE_AUTO, PX4_AUTO_SUB_MODE_LOITER = 4, 3
#: PX4 ``vehicle_status.nav_state`` → the custom (main, sub) mode DO_SET_MODE selects it with,
#: and its name in QGroundControl (px4_custom_mode.h, ``get_px4_custom_mode``).
PX4_MODES: dict[int, tuple[int, int, str]] = {
    0: (1, 0, "Manual"), 1: (2, 0, "Altitude"), 2: (3, 0, "Position"), 3: (4, 4, "Mission"),
    4: (4, 3, "Hold"), 5: (4, 5, "Return"), 10: (5, 0, "Acro"), 14: (6, 0, "Offboard"),
    15: (7, 0, "Stabilized"), 17: (4, 2, "Takeoff"), 18: (4, 6, "Land"),
    19: (4, 8, "Follow Me"), 20: (4, 9, "Precision Land"),
}  # fmt: skip
#: How many times an arm is asked again, a HEARTBEAT (1 s) apart, while PX4 is not ready.
ARM_READY_RETRIES = 30
#: How long (simulated time) a polled conversation waits for the autopilot's first
#: HEARTBEAT before its first message. PX4 starts its MAVLink links from its start-up
#: script, in wall time, while its lockstep clock already runs: on a loaded machine the
#: first simulated second can pass before its onboard link listens, and a message sent
#: earlier is lost (UDP), as a MISSION_COUNT at t = 1 s once was.
AUTOPILOT_HEARD_TIMEOUT_SIM_S = 30.0
#: Period of the offboard setpoint keep-alive: PX4 leaves offboard after COM_OF_LOSS_T (1 s).
OFFBOARD_KEEPALIVE_S = 0.1

_POSITION_ONLY = (
    mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)  # fmt: skip
_VELOCITY_ONLY = (
    mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_AY_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)  # fmt: skip
_ATTITUDE_ONLY = (
    mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
)
#: PX4 flies the body rates of a SET_ATTITUDE_TARGET whose attitude is ignored.
_RATES_ONLY = mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE


@dataclass(frozen=True)
class MissionItem:
    """One MISSION_ITEM_INT: ``command`` (MAV_CMD) at a global position, its altitude in
    ``frame`` (MAV_FRAME: above home for the RELATIVE_ALT frames, else AMSL)."""

    frame: int
    command: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    param1: float = 0.0  # NAV_WAYPOINT: hold time (s)
    param2: float = 0.0  # acceptance radius (m); 0: the autopilot's default
    param3: float = 0.0
    param4: float = math.nan  # yaw (deg); NaN: the autopilot's choice


@dataclass(frozen=True)
class Expect:
    """Send ``send``, then wait for the first incoming message ``accept`` returns True for."""

    send: tuple[mavlink.MAVLink_message, ...]
    accept: Callable[[mavlink.MAVLink_message], bool]
    waiting_for: str


Conversation = Generator[Expect, mavlink.MAVLink_message, str]


@dataclass
class _Pending:
    conversation: Conversation
    step: Expect
    name: str
    started_s: float
    sent: bool


@dataclass
class GroundLink:
    """The API-link socket and the scenario actions it can perform."""

    ports: Ports
    home: GeoPoint
    ack_timeout_s: float = 5.0
    ack_timeout_sim_s: float = 10.0
    #: Latest STATUSTEXT from the autopilot: quoted when a command is refused.
    last_statustext: str = ""
    #: The autopilot's latest HEARTBEAT ``custom_mode`` (its flight mode, PX4's encoding).
    custom_mode: int | None = None
    received: dict[str, int] = field(default_factory=dict)
    #: Messages sent to the autopilot so far.
    messages_sent: int = 0

    def __post_init__(self) -> None:
        self.mav = mavlink.MAVLink(None, GCS_SYSTEM_ID, GCS_COMPONENT_ID)
        self.mav.robust_parsing = True
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind(("127.0.0.1", self.ports.onboard_remote_udp))
        except OSError as error:
            self._sock.close()
            raise GroundLinkError(
                f"cannot bind the onboard link UDP 127.0.0.1:{self.ports.onboard_remote_udp} "
                f"({error.strerror}); is another rig using instance {self.ports.instance}?"
            ) from None
        self._target = ("127.0.0.1", self.ports.onboard_local_udp)
        self._pending: _Pending | None = None
        #: Per parameter, the values set earlier in this run (:meth:`set_param`).
        self._params_set: dict[str, set[float]] = {}

    # -- drivers ---------------------------------------------------------------------------

    def converse_now(self, name: str, conversation: Conversation) -> str:
        """Run a conversation to its end, waiting in wall time (reference autopilot)."""
        self._drain()  # telemetry queued since the last frame; a STATUSTEXT may explain
        step = next(conversation)
        while True:
            self._send(step.send)
            deadline = time.monotonic() + self.ack_timeout_s
            answer = None
            while answer is None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise GroundLinkError(
                        f"{name}: no {step.waiting_for} from the autopilot on UDP "
                        f"{self._target[1]} within {self.ack_timeout_s:g} s of wall time "
                        "(the rig holds the next sensor frame until it arrives)"
                    )
                answer = self._receive_matching(step, remaining)
            try:
                step = conversation.send(answer)
            except StopIteration as done:
                return done.value

    def start(self, name: str, conversation: Conversation, time_s: float) -> str:
        """Begin a conversation that :meth:`poll` advances frame by frame (PX4 SITL); its
        first message waits for the autopilot's first HEARTBEAT. Returns what was done."""
        if self._pending is not None:
            raise GroundLinkError(
                f"{name} at t={time_s:.3f} s: {self._pending.name} is still waiting for "
                f"{self._pending.step.waiting_for}"
            )
        self._pending = _Pending(conversation, next(conversation), name, time_s, sent=False)
        if self._send_first_if_heard(time_s):
            return "sent"
        return f"held until the autopilot's first HEARTBEAT on UDP {self.ports.onboard_remote_udp}"

    def _send_first_if_heard(self, time_s: float) -> bool:
        """Send the pending conversation's first message once the autopilot has been heard."""
        pending = self._pending
        assert pending is not None
        self._drain()  # a HEARTBEAT queued since the last frame is what we wait for
        if self.autopilot_heard:
            self._send(pending.step.send)
            pending.sent, pending.started_s = True, time_s
        return pending.sent

    @property
    def autopilot_heard(self) -> bool:
        """Whether an autopilot's HEARTBEAT has arrived: its onboard link listens."""
        return self.custom_mode is not None

    @property
    def busy(self) -> bool:
        return self._pending is not None

    def poll(self, time_s: float) -> str | None:
        """Advance the pending conversation with what has arrived; its result when done."""
        pending = self._pending
        if pending is None:
            self._drain()
            return None
        if not pending.sent and not self._send_first_if_heard(time_s):
            if time_s - pending.started_s > AUTOPILOT_HEARD_TIMEOUT_SIM_S:
                raise GroundLinkError(
                    f"{pending.name}: no HEARTBEAT from the autopilot on UDP "
                    f"{self.ports.onboard_remote_udp} within {AUTOPILOT_HEARD_TIMEOUT_SIM_S:g} s "
                    "of simulated time (its onboard MAVLink link never started)"
                )
            return None
        while (answer := self._receive_matching(pending.step, 0.0)) is not None:
            try:
                pending.step = pending.conversation.send(answer)
            except StopIteration as done:
                self._pending = None
                return done.value
            self._send(pending.step.send)
            pending.started_s = time_s
        if time_s - pending.started_s > self.ack_timeout_sim_s:
            raise GroundLinkError(
                f"{pending.name}: no {pending.step.waiting_for} from the autopilot within "
                f"{self.ack_timeout_sim_s:g} s of simulated time"
            )
        return None

    def send_unacknowledged(self, messages: Sequence[mavlink.MAVLink_message]) -> None:
        self._send(messages)

    def close(self) -> None:
        self._sock.close()

    # -- conversations ---------------------------------------------------------------------

    def command(self, command: int, *params: float, what: str) -> Conversation:
        """COMMAND_LONG → COMMAND_ACK; anything but ACCEPTED is a refusal with the reason."""
        ack = yield self._command_step(command, *params)
        return self._accepted(ack, what)

    def _command_step(self, command: int, *params: float) -> Expect:
        padded = [*params, *[0.0] * (7 - len(params))]
        message = self.mav.command_long_encode(
            self.ports.system_id, 1, command, 0, *padded
        )  # fmt: skip
        return Expect(
            (message,),
            lambda m: m.get_type() == "COMMAND_ACK" and m.command == command,
            f"COMMAND_ACK for {_enum_name('MAV_CMD', command)}",
        )

    def _accepted(self, ack: mavlink.MAVLink_message, what: str) -> str:
        if ack.result != mavlink.MAV_RESULT_ACCEPTED:
            reason = f" ({self.last_statustext})" if self.last_statustext else ""
            raise GroundLinkError(
                f"the autopilot refused {what}: {_enum_name('MAV_RESULT', ack.result)}{reason}"
            )
        return f"{what}: accepted"

    def attempt(self, conversation: Conversation) -> Conversation:
        """``conversation`` with a refusal as its result, not an error: the run goes on. A
        missing answer still ends the run (the drivers raise that, not the conversation)."""
        try:
            return (yield from conversation)
        except GroundLinkError as refusal:
            return f"{refusal}; the run goes on"

    def arm(self, arm: bool = True) -> Conversation:
        return self.command(
            mavlink.MAV_CMD_COMPONENT_ARM_DISARM, float(arm), what="arm" if arm else "disarm"
        )

    def arm_when_ready(self) -> Conversation:
        """Arm as a pilot arms PX4: while it answers TEMPORARILY_REJECTED (its pre-flight
        checks have not passed yet: EKF2 still aligning, GPS not yet good enough), wait for
        its next HEARTBEAT (1 s of its clock) and ask again, up to ARM_READY_RETRIES times.

        Only where the rig keeps stepping while it waits (:meth:`poll`); the reference
        autopilot's clock stands still in :meth:`converse_now`.
        """
        command = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
        for _ in range(ARM_READY_RETRIES):
            ack = yield self._command_step(command, 1.0)
            if ack.result != mavlink.MAV_RESULT_TEMPORARILY_REJECTED:
                break
            yield Expect((), lambda m: m.get_type() == "HEARTBEAT",
                         "HEARTBEAT (waiting until it is ready to arm)")  # fmt: skip
        return self._accepted(ack, "arm")

    def takeoff(self, altitude_m: float) -> Conversation:
        """MAVSDK's way: MIS_TAKEOFF_ALT, then NAV_TAKEOFF with a NaN altitude.

        NaN tells PX4 to climb MIS_TAKEOFF_ALT above the home *it* set at arming (from its
        own GPS/baro), so the height is right even when its home altitude is off by the
        GPS's vertical error; an AMSL altitude computed here would not be.
        """
        yield from self.set_param("MIS_TAKEOFF_ALT", altitude_m)
        return (
            yield from self.command(
                mavlink.MAV_CMD_NAV_TAKEOFF, -1.0, 0.0, 0.0, math.nan, math.nan, math.nan,
                math.nan, what=f"takeoff to {altitude_m:g} m",
            )
        )  # fmt: skip

    def set_home(self, home: GeoPoint) -> Conversation:
        """DO_SET_HOME to ``home`` as a COMMAND_INT (whole-degE7 latitude and longitude: a
        COMMAND_LONG's float params would move it by up to 0.5 m), as QGroundControl's "Set
        Home here" does."""
        command = mavlink.MAV_CMD_DO_SET_HOME
        message = self.mav.command_int_encode(
            self.ports.system_id, 1, mavlink.MAV_FRAME_GLOBAL, command, 0, 0,
            0.0, 0.0, 0.0, math.nan, round(home.lat_deg * 1e7), round(home.lon_deg * 1e7),
            home.alt_amsl_m,
        )  # fmt: skip
        ack = yield Expect(
            (message,),
            lambda m: m.get_type() == "COMMAND_ACK" and m.command == command,
            f"COMMAND_ACK for {_enum_name('MAV_CMD', command)}",
        )
        return self._accepted(ack, f"home at {home.alt_amsl_m:.2f} m AMSL")

    def land(self) -> Conversation:
        return self.command(mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan, math.nan, math.nan,
                            math.nan, what="land")  # fmt: skip

    def hold(self) -> Conversation:
        """DO_SET_MODE(Hold), as QGroundControl's mode menu and MAVSDK's ``hold()``."""
        return self.command(
            mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            PX4_MAIN_MODE_AUTO, PX4_AUTO_SUB_MODE_LOITER, what="hold",
        )  # fmt: skip

    def set_mode(self, nav_state: int) -> Conversation:
        """DO_SET_MODE to the PX4 flight mode ``nav_state`` (:data:`PX4_MODES`), as a ground
        station's mode menu does."""
        main, sub, name = PX4_MODES[nav_state]
        return self.command(
            mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub,
            what=f"mode {name}",
        )  # fmt: skip

    def offboard(self, setpoints: Sequence[mavlink.MAVLink_message], what: str) -> Conversation:
        """Setpoints, then DO_SET_MODE(OFFBOARD): the ACK also proves they were handled."""
        conversation = self.command(
            mavlink.MAV_CMD_DO_SET_MODE,
            mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            PX4_MAIN_MODE_OFFBOARD,
            what=what,
        )
        step = next(conversation)
        answer = yield Expect((*setpoints, *step.send), step.accept, step.waiting_for)
        try:
            conversation.send(answer)
        except StopIteration as done:
            return done.value
        raise AssertionError("a command conversation has one step")

    def position_setpoint(
        self, position_ned_m: Sequence[float], yaw_deg: float | None, time_s: float
    ) -> mavlink.MAVLink_message:
        mask = _POSITION_ONLY | (
            mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE if yaw_deg is None else 0
        )
        north, east, down = (float(v) for v in position_ned_m)
        return self.mav.set_position_target_local_ned_encode(
            round(time_s * 1000), self.ports.system_id, 1, mavlink.MAV_FRAME_LOCAL_NED, mask,
            north, east, down, 0, 0, 0, 0, 0, 0, math.radians(yaw_deg or 0.0), 0,
        )  # fmt: skip

    def velocity_setpoint(
        self, velocity_ned_mps: Sequence[float], yaw_rad: float | None, time_s: float
    ) -> mavlink.MAVLink_message:
        """Velocity (and yaw unless None) in LOCAL_NED; the position is not controlled."""
        mask = _VELOCITY_ONLY | (mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE if yaw_rad is None
                                 else 0)  # fmt: skip
        vn, ve, vd = (float(v) for v in velocity_ned_mps)
        return self.mav.set_position_target_local_ned_encode(
            round(time_s * 1000), self.ports.system_id, 1, mavlink.MAV_FRAME_LOCAL_NED, mask,
            0, 0, 0, vn, ve, vd, 0, 0, 0, yaw_rad or 0.0, 0,
        )  # fmt: skip

    def attitude_setpoint(
        self, roll_rad: float, pitch_rad: float, yaw_rad: float, thrust: float, time_s: float
    ) -> mavlink.MAVLink_message:
        return self.quaternion_setpoint(quat_from_euler(roll_rad, pitch_rad, yaw_rad), thrust,
                                        time_s)  # fmt: skip

    def quaternion_setpoint(
        self, q: Iterable[float], thrust: float, time_s: float
    ) -> mavlink.MAVLink_message:
        """Attitude (body to NED, w x y z) and collective thrust 0..1."""
        return self.mav.set_attitude_target_encode(
            round(time_s * 1000), self.ports.system_id, 1, _ATTITUDE_ONLY,
            [float(c) for c in q], 0.0, 0.0, 0.0, float(thrust),
        )  # fmt: skip

    def rates_setpoint(
        self, rates_frd_radps: Sequence[float], thrust: float, time_s: float
    ) -> mavlink.MAVLink_message:
        """Body rates (FRD) and collective thrust 0..1; the attitude is ignored."""
        roll, pitch, yaw = (float(r) for r in rates_frd_radps)
        return self.mav.set_attitude_target_encode(
            round(time_s * 1000), self.ports.system_id, 1, _RATES_ONLY,
            [1.0, 0.0, 0.0, 0.0], roll, pitch, yaw, float(thrust),
        )  # fmt: skip

    def manual_control(
        self, roll: float, pitch: float, yaw: float, throttle: float
    ) -> mavlink.MAVLink_message:
        """A pilot's sticks in PX4's convention (``manual_control_setpoint``: −1..1, throttle
        −1 at idle) as MANUAL_CONTROL; beyond ±1 is held at the stop, as a stick is."""

        def axis(value: float) -> int:
            return round(1000 * min(max(value, -1.0), 1.0))

        return self.mav.manual_control_encode(
            self.ports.system_id, axis(pitch), axis(roll), (axis(throttle) + 1000) // 2,
            axis(yaw), 0,
        )  # fmt: skip

    def heartbeat(self) -> mavlink.MAVLink_message:
        """The ground station's HEARTBEAT (1 Hz, as QGroundControl sends it): PX4 counts a
        ground station as connected while it hears one, which NAV_DLL_ACT needs to arm."""
        return self.mav.heartbeat_encode(
            mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE
        )

    def motor_test(self, motor: int, throttle: float, duration_s: float) -> Conversation:
        return self.command(
            mavlink.MAV_CMD_DO_MOTOR_TEST, motor + 1, mavlink.MOTOR_TEST_THROTTLE_PERCENT,
            throttle * 100.0, duration_s, 0, mavlink.MOTOR_TEST_ORDER_DEFAULT,
            what=f"motor test of motor {motor} at {throttle:.0%}",
        )  # fmt: skip

    def mission(self, waypoints_ned_m: Sequence[Sequence[float]]) -> Conversation:
        """Upload waypoints (MISSION_COUNT/REQUEST/ITEM_INT/ACK), then MISSION_START."""
        items = []
        for north, east, down in waypoints_ned_m:
            lat, lon, _ = ned_to_geodetic(
                (north, east, down), self.home.lat_deg, self.home.lon_deg, self.home.alt_amsl_m
            )
            items.append(MissionItem(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                     mavlink.MAV_CMD_NAV_WAYPOINT, lat, lon, float(-down),
                                     param2=1.0))  # fmt: skip
        yield from self.upload_mission(items)
        return (yield from self.command(mavlink.MAV_CMD_MISSION_START, 0, 0,
                                        what=f"mission of {len(items)} waypoints"))  # fmt: skip

    def upload_mission(self, items: Sequence[MissionItem]) -> Conversation:
        """The mission protocol's upload (MISSION_COUNT, then each MISSION_ITEM_INT PX4 asks
        for, until MISSION_ACK); the mission starts when a mode or MISSION_START says so."""
        target = self.ports.system_id
        encoded = [
            self.mav.mission_item_int_encode(
                target, 1, seq, item.frame, item.command, 0, 1, item.param1, item.param2,
                item.param3, item.param4, round(item.lat_deg * 1e7), round(item.lon_deg * 1e7),
                float(item.alt_m),
            )
            for seq, item in enumerate(items)
        ]  # fmt: skip
        message = self.mav.mission_count_encode(target, 1, len(encoded))
        while True:
            answer = yield Expect(
                (message,),
                lambda m: m.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"),
                "MISSION_REQUEST_INT or MISSION_ACK",
            )
            if answer.get_type() == "MISSION_ACK":
                break
            if not 0 <= answer.seq < len(encoded):
                raise GroundLinkError(
                    f"mission upload: the autopilot asked for item {answer.seq} of {len(encoded)}"
                )
            message = encoded[answer.seq]
        if answer.type != mavlink.MAV_MISSION_ACCEPTED:
            raise GroundLinkError(
                f"the autopilot refused the mission: {_enum_name('MAV_MISSION', answer.type)}"
            )
        return f"mission of {len(encoded)} items uploaded"

    def set_param(self, name: str, value: float) -> Conversation:
        """PARAM_SET → PARAM_VALUE echo; PX4 answers with the value it actually took.

        PX4 announces a changed parameter a second time, so a PARAM_VALUE carrying a value
        set earlier in this run may be that announcement, not the answer: it is passed over
        (if PX4 did keep the old value, the wait for the new one times out)."""
        encoded = name.encode()
        message = self.mav.param_set_encode(
            self.ports.system_id, 1, encoded, float(value), mavlink.MAV_PARAM_TYPE_REAL32
        )
        sent = _float32(value)  # as PARAM_VALUE carries it
        earlier = self._params_set.setdefault(name, set()) - {sent}
        answer = yield Expect(
            (message,),
            lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name,
            f"PARAM_VALUE for {name}",
        )
        while answer.param_value in earlier:
            answer = yield Expect(
                (),
                lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name,
                f"PARAM_VALUE for {name} = {value:g} (it announced an earlier value "
                f"{answer.param_value:g})",
            )
        if not math.isclose(answer.param_value, value, rel_tol=1e-6, abs_tol=1e-9):
            raise GroundLinkError(
                f"the autopilot kept {name} = {answer.param_value:g} instead of {value:g}"
            )
        self._params_set[name].add(sent)
        return f"{name} = {value:g}"

    # -- socket ----------------------------------------------------------------------------

    def _send(self, messages: Sequence[mavlink.MAVLink_message]) -> None:
        for message in messages:
            self._sock.sendto(message.pack(self.mav), self._target)
            self.messages_sent += 1

    def _receive_matching(self, step: Expect, timeout_s: float) -> mavlink.MAVLink_message | None:
        """Handle what arrives within ``timeout_s``; return the first message ``step`` wants."""
        deadline = time.monotonic() + timeout_s
        while True:
            ready, _, _ = select.select([self._sock], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                return None
            data = self._sock.recv(65536)
            for message in self.mav.parse_buffer(data) or ():
                kind = message.get_type()
                self.received[kind] = self.received.get(kind, 0) + 1
                if kind == "HEARTBEAT" and message.autopilot != mavlink.MAV_AUTOPILOT_INVALID:
                    self.custom_mode = message.custom_mode  # not a GCS's or companion's
                if kind == "STATUSTEXT":
                    self.last_statustext = message.text
                elif step.accept(message):
                    return message

    def _drain(self) -> None:
        never = Expect((), lambda m: False, "")
        self._receive_matching(never, 0.0)


def _enum_name(enum: str, value: int) -> str:
    entry = mavlink.enums[enum].get(value)
    return f"{entry.name} ({value})" if entry is not None else f"{enum} {value}"


def sweep_pitch_rad(time_s: float, duration_s: float, amplitude_rad: float,
                    f_min_radps: float, f_max_radps: float) -> float:  # fmt: skip
    """Logarithmic chirp from ``f_min`` to ``f_max`` over ``duration_s`` (0 outside).

    The instantaneous frequency is ω(t) = ω₀·k^(t/T) with k = ω₁/ω₀, so the phase is
    ω₀·T·(k^(t/T) − 1)/ln k: equal time per octave, as frequency-sweep tests (CIFER
    practice) use, so each decade gets the same share of data.
    """
    if not 0.0 <= time_s <= duration_s:
        return 0.0
    ratio = f_max_radps / f_min_radps
    phase = f_min_radps * duration_s * (ratio ** (time_s / duration_s) - 1.0) / math.log(ratio)
    return amplitude_rad * math.sin(phase)


def _float32(value: float) -> float:
    """``value`` rounded to MAVLink's float as a PARAM_VALUE carries it."""
    return struct.unpack("<f", struct.pack("<f", value))[0]
