"""The ground-station side: MAVLink over UDP as PX4 SITL serves it.

Three links per instance (``Ports``), as PX4 SITL opens them: the GCS link binds 18570+i
and talks to 14550 (QGroundControl, MAVProxy), the API link binds 14580+i and talks to
14540+i (MAVSDK, scripts), the onboard link binds 14280+i and talks to 14030+i (the rig's
scenario commands, as a companion computer's). Each answers whoever last talked to it.
Telemetry is paced by simulated time (the autopilot's only clock), so a run's messages do
not depend on the wall clock.

Protocols follow PX4's ``mavlink`` module and MAVLink's ``common.xml``: commands with
COMMAND_ACK, the mission protocol (upload and download, MISSION_CURRENT and
MISSION_ITEM_REACHED), the parameter protocol with PX4's bytewise int32 encoding, and
offboard set-points. Malformed or unexpected messages are counted and ignored.
"""

from __future__ import annotations

import contextlib
import math
import socket
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from quad_model.frames import euler_from_quat
from rig.autopilots.reference.flight_controller import CommandResult, FlightController
from rig.autopilots.reference.navigator import (
    MissionItem,
    NavState,
    check_mission_item,
    custom_mode,
)
from rig.autopilots.reference.navigator import nav_state_from_custom as _mode_from_custom
from rig.autopilots.reference.params import ParameterError
from rig.mavlink.px4_api import mavlink

#: Default telemetry intervals (µs) per message, like PX4's "normal" stream set for UDP.
DEFAULT_INTERVALS_US = {
    "HEARTBEAT": 1_000_000,
    "SYS_STATUS": 1_000_000,
    "EXTENDED_SYS_STATE": 1_000_000,
    "ATTITUDE": 100_000,
    "LOCAL_POSITION_NED": 100_000,
    "GLOBAL_POSITION_INT": 200_000,
    "HOME_POSITION": 2_000_000,
    "MISSION_CURRENT": 1_000_000,
}
_MESSAGE_IDS = {name: getattr(mavlink, f"MAVLINK_MSG_ID_{name}") for name in DEFAULT_INTERVALS_US}
_NAMES_BY_ID = {v: k for k, v in _MESSAGE_IDS.items()}
#: Mission transfer: re-request an item after this much wall time, at most this often.
MISSION_RETRY_S, MISSION_RETRIES = 1.0, 5
_SENSORS = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO, mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
            mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG, mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE,
            mavlink.MAV_SYS_STATUS_SENSOR_GPS)  # fmt: skip
_MONITOR_KEYS = ("gyro", "accel", "mag", "baro", "gps")
_RATES_IGNORED = (
    mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
)
_CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
)  # fmt: skip


@dataclass
class _Upload:
    """A mission upload in progress on one link."""

    count: int
    peer: tuple[int, int]  # the uploader's system and component ids
    items: list[MissionItem] = field(default_factory=list)
    last_request_s: float = 0.0
    retries: int = 0


class MavlinkLink:
    """One UDP endpoint: a bound socket, the peer it answers, and its own stream rates."""

    def __init__(self, name: str, bind_port: int, remote_port: int, system_id: int) -> None:
        self.name = name
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", bind_port))
        self.sock.setblocking(False)
        self.peer: tuple[str, int] = ("127.0.0.1", remote_port)
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=1)
        self.mav.robust_parsing = True
        self.intervals_us = dict(DEFAULT_INTERVALS_US)
        self.next_send_us = dict.fromkeys(DEFAULT_INTERVALS_US, 0)
        self.upload: _Upload | None = None

    def receive(self) -> list[object]:
        """All messages waiting on the socket (bad data included, as ``BAD_DATA``).

        The link answers the sender of the last valid message: garbage from elsewhere (a
        port scan, a fuzzer) does not steal the ground station's telemetry.
        """
        messages: list[object] = []
        while True:
            try:
                data, address = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return messages
            except OSError:  # e.g. ICMP port unreachable reported on a later call
                continue
            parsed = self.mav.parse_buffer(data) or []
            if any(message.get_type() != "BAD_DATA" for message in parsed):
                self.peer = address
            messages.extend(parsed)

    def send(self, message) -> None:
        # nobody listening (yet) is fine: UDP telemetry is fire-and-forget, as in PX4
        with contextlib.suppress(OSError):
            self.sock.sendto(message.pack(self.mav), self.peer)

    def close(self) -> None:
        self.sock.close()


class GroundStation:
    """Serves the flight controller to ground stations on one or more links."""

    def __init__(self, controller: FlightController, links: list[MavlinkLink]) -> None:
        self.fc = controller
        self.links = links
        self.malformed = 0
        self.unexpected = 0
        self._handlers: dict[str, Callable[[MavlinkLink, object], None]] = {
            "HEARTBEAT": lambda link, msg: None,
            "COMMAND_LONG": self._command_long,
            "COMMAND_INT": self._command_int,
            "PARAM_REQUEST_LIST": self._param_request_list,
            "PARAM_REQUEST_READ": self._param_request_read,
            "PARAM_SET": self._param_set,
            "MISSION_COUNT": self._mission_count,
            "MISSION_ITEM_INT": self._mission_item_int,
            "MISSION_REQUEST_LIST": self._mission_request_list,
            "MISSION_REQUEST_INT": self._mission_request,
            "MISSION_REQUEST": self._mission_request,
            "MISSION_CLEAR_ALL": self._mission_clear_all,
            "MISSION_SET_CURRENT": self._mission_set_current,
            "MISSION_ACK": lambda link, msg: None,
            "SET_POSITION_TARGET_LOCAL_NED": self._set_position_target,
            "SET_ATTITUDE_TARGET": self._set_attitude_target,
        }

    # ------------------------------------------------------------------ receive
    def handle(self, link: MavlinkLink, message) -> None:
        """Dispatch one message; anything malformed or unknown is counted, never raised."""
        kind = message.get_type()
        if kind == "BAD_DATA":
            self.malformed += 1
            return
        handler = self._handlers.get(kind)
        if handler is None or not self._for_us(message):
            self.unexpected += 1
            return
        try:
            handler(link, message)
        except (ValueError, TypeError, OverflowError, struct.error, UnicodeError):
            self.malformed += 1  # e.g. NaN where an integer is needed: a broken sender
        self.flush_events()

    def _for_us(self, message) -> bool:
        target = getattr(message, "target_system", 0)
        return target in (0, self.fc.params["MAV_SYS_ID"])

    # ------------------------------------------------------------------ commands
    def _command_long(self, link: MavlinkLink, msg) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                  msg.param7)  # fmt: skip
        self._command(link, msg, msg.command, params)

    def _command_int(self, link: MavlinkLink, msg) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x * 1e-7, msg.y * 1e-7,
                  msg.z)  # fmt: skip
        self._command(link, msg, msg.command, params)

    def _command(self, link: MavlinkLink, msg, command: int, p: tuple[float, ...]) -> None:
        try:
            result = self._run_command(link, command, p)
        except (ValueError, OverflowError):  # NaN or ∞ where a mode or index was needed
            self.malformed += 1
            result = CommandResult(mavlink.MAV_RESULT_DENIED)
        self.flush_events()  # a refusal's reason goes out before its ACK
        link.send(mavlink.MAVLink_command_ack_message(
            command, result.result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()))  # fmt: skip

    def _run_command(self, link: MavlinkLink, command: int, p: tuple[float, ...]):
        fc = self.fc
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            force = round(p[1]) == 21196 if math.isfinite(p[1]) else False
            result = fc.arm(force) if p[0] > 0.5 else fc.disarm(force)
        elif command == mavlink.MAV_CMD_NAV_TAKEOFF:
            result = fc.takeoff(p[6])
        elif command == mavlink.MAV_CMD_NAV_LAND:
            result = fc.land()
        elif command == mavlink.MAV_CMD_DO_SET_MODE:
            result = self._set_mode(p)
        elif command == mavlink.MAV_CMD_MISSION_START:
            first = int(p[0]) if math.isfinite(p[0]) and p[0] > 0 else None
            if first is not None:
                fc.set_mission_current(first)
            result = fc.set_mode(NavState.AUTO_MISSION)
        elif command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_interval(link, int(p[0]), p[1])
        elif command in (mavlink.MAV_CMD_REQUEST_MESSAGE,
                         mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):  # fmt: skip
            wanted = mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
                wanted = int(p[0])
            result = self._send_once(link, wanted)
        elif command == mavlink.MAV_CMD_DO_MOTOR_TEST:
            result = fc.motor_test(int(p[0]) - 1, p[2] / 100.0, p[3])
        else:
            result = CommandResult(mavlink.MAV_RESULT_UNSUPPORTED)
        return result

    def _set_mode(self, p: tuple[float, ...]) -> CommandResult:
        if not int(p[0]) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return CommandResult(mavlink.MAV_RESULT_UNSUPPORTED)
        nav_state = _mode_from_custom(int(p[1]), int(p[2]))
        if nav_state is None:
            return self.fc.refuse(f"Mode {int(p[1])}/{int(p[2])} not available (no RC pilot)")
        return self.fc.set_mode(nav_state)

    def _set_interval(self, link: MavlinkLink, message_id: int, interval_us: float):
        name = _NAMES_BY_ID.get(message_id)
        if name is None:
            return CommandResult(mavlink.MAV_RESULT_UNSUPPORTED)
        if interval_us == 0:
            link.intervals_us[name] = DEFAULT_INTERVALS_US[name]
        elif interval_us < 0:
            link.intervals_us[name] = -1
        else:
            link.intervals_us[name] = int(interval_us)
        return CommandResult(mavlink.MAV_RESULT_ACCEPTED)

    def _send_once(self, link: MavlinkLink, message_id: int) -> CommandResult:
        if message_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            link.send(mavlink.MAVLink_autopilot_version_message(
                _CAPABILITIES, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0,
                self.fc.params["MAV_SYS_ID"]))  # fmt: skip
            return CommandResult(mavlink.MAV_RESULT_ACCEPTED)
        name = _NAMES_BY_ID.get(message_id)
        message = self._telemetry(name) if name else None
        if message is None:
            return CommandResult(mavlink.MAV_RESULT_UNSUPPORTED)
        link.send(message)
        return CommandResult(mavlink.MAV_RESULT_ACCEPTED)

    # ------------------------------------------------------------------ parameters
    def _param_value(self, name: str):
        params = self.fc.params
        value = params[name]
        if params.spec(name).is_int:  # PX4 sends int32 bit patterns in the float field
            encoded = struct.unpack("<f", struct.pack("<i", int(value)))[0]
            kind = mavlink.MAV_PARAM_TYPE_INT32
        else:
            encoded, kind = float(value), mavlink.MAV_PARAM_TYPE_REAL32
        return mavlink.MAVLink_param_value_message(
            name.encode(), encoded, kind, len(params), params.index(name)
        )

    def _param_request_list(self, link: MavlinkLink, msg) -> None:
        for name in self.fc.params:
            link.send(self._param_value(name))

    def _param_request_read(self, link: MavlinkLink, msg) -> None:
        try:
            name = (self.fc.params.name_at(msg.param_index) if msg.param_index >= 0
                    else _param_id(msg.param_id))  # fmt: skip
            link.send(self._param_value(name))
        except ParameterError as error:
            self.fc.notify(mavlink.MAV_SEVERITY_WARNING, str(error))

    def _param_set(self, link: MavlinkLink, msg) -> None:
        name = _param_id(msg.param_id)
        value = msg.param_value
        if msg.param_type == mavlink.MAV_PARAM_TYPE_INT32:
            value = struct.unpack("<i", struct.pack("<f", value))[0]
        try:
            self.fc.set_parameter(name, value)
        except ParameterError as error:
            self.fc.notify(mavlink.MAV_SEVERITY_WARNING, str(error))
            if name not in self.fc.params:
                return
        link.send(self._param_value(name))  # the value it holds now, as PX4 answers

    # ------------------------------------------------------------------ missions
    def _mission_count(self, link: MavlinkLink, msg) -> None:
        if getattr(msg, "mission_type", 0) != mavlink.MAV_MISSION_TYPE_MISSION:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_UNSUPPORTED)
            return
        if msg.count == 0:
            self.fc.set_mission([])
            self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED)
            return
        link.upload = _Upload(msg.count, (msg.get_srcSystem(), msg.get_srcComponent()))
        self._request_item(link)

    def _request_item(self, link: MavlinkLink) -> None:
        upload = link.upload
        upload.last_request_s = time.monotonic()
        link.send(mavlink.MAVLink_mission_request_int_message(
            *upload.peer, len(upload.items), mavlink.MAV_MISSION_TYPE_MISSION))  # fmt: skip

    def _mission_item_int(self, link: MavlinkLink, msg) -> None:
        upload = link.upload
        if upload is None:
            self.unexpected += 1
            return
        if msg.seq != len(upload.items):  # a duplicate or out of order: ask again
            self._request_item(link)
            return
        item = MissionItem(msg.seq, msg.frame, msg.command, msg.param1, msg.param2, msg.param3,
                           msg.param4, msg.x, msg.y, msg.z, msg.autocontinue)  # fmt: skip
        verdict = check_mission_item(item)
        if verdict != mavlink.MAV_MISSION_ACCEPTED:
            link.upload = None
            self.fc.notify(
                mavlink.MAV_SEVERITY_WARNING,
                f"Mission item {msg.seq} rejected (command {msg.command})",
            )
            self.flush_events()
            self._mission_ack(link, msg, verdict)
            return
        upload.items.append(item)
        upload.retries = 0
        if len(upload.items) < upload.count:
            self._request_item(link)
            return
        link.upload = None
        self.fc.set_mission(upload.items)
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED)
        link.send(self._telemetry("MISSION_CURRENT"))

    def _mission_ack(self, link: MavlinkLink, msg, result: int) -> None:
        link.send(mavlink.MAVLink_mission_ack_message(
            msg.get_srcSystem(), msg.get_srcComponent(), result,
            mavlink.MAV_MISSION_TYPE_MISSION))  # fmt: skip

    def _mission_request_list(self, link: MavlinkLink, msg) -> None:
        link.send(mavlink.MAVLink_mission_count_message(
            msg.get_srcSystem(), msg.get_srcComponent(), len(self.fc.navigator.mission),
            mavlink.MAV_MISSION_TYPE_MISSION))  # fmt: skip

    def _mission_request(self, link: MavlinkLink, msg) -> None:
        mission = self.fc.navigator.mission
        if not 0 <= msg.seq < len(mission):
            self._mission_ack(link, msg, mavlink.MAV_MISSION_INVALID_SEQUENCE)
            return
        i = mission[msg.seq]
        link.send(mavlink.MAVLink_mission_item_int_message(
            msg.get_srcSystem(), msg.get_srcComponent(), i.seq, i.frame, i.command,
            int(i.seq == self.fc.navigator.mission_seq), i.autocontinue, i.param1, i.param2,
            i.param3, i.param4, i.x, i.y, i.z, mavlink.MAV_MISSION_TYPE_MISSION))  # fmt: skip

    def _mission_clear_all(self, link: MavlinkLink, msg) -> None:
        self.fc.set_mission([])
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED)

    def _mission_set_current(self, link: MavlinkLink, msg) -> None:
        if not self.fc.set_mission_current(msg.seq):
            self._mission_ack(link, msg, mavlink.MAV_MISSION_INVALID_SEQUENCE)

    def retry_uploads(self) -> None:
        """Re-request a mission item the ground station did not send (UDP can lose it)."""
        now = time.monotonic()
        for link in self.links:
            upload = link.upload
            if upload is None or now - upload.last_request_s < MISSION_RETRY_S:
                continue
            if upload.retries >= MISSION_RETRIES:
                link.upload = None
                self.fc.notify(mavlink.MAV_SEVERITY_WARNING, "Mission upload timed out")
                continue
            upload.retries += 1
            self._request_item(link)

    # ------------------------------------------------------------------ offboard
    def _set_position_target(self, link: MavlinkLink, msg) -> None:
        if msg.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
            self.unexpected += 1
            return
        mask = msg.type_mask
        position = np.array([msg.x, msg.y, msg.z], dtype=float)
        velocity = np.array([msg.vx, msg.vy, msg.vz], dtype=float)
        for bit, array, index in (
            (1, position, 0),
            (2, position, 1),
            (4, position, 2),
            (8, velocity, 0),
            (16, velocity, 1),
            (32, velocity, 2),
        ):
            if mask & bit:
                array[index] = np.nan  # fmt: skip
        yaw = math.nan if mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE else msg.yaw
        yaw_rate = (math.nan if mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
                    else msg.yaw_rate)  # fmt: skip
        if not (np.isfinite(position).any() or np.isfinite(velocity).any()):
            self.unexpected += 1
            return
        self.fc.set_offboard_setpoint(position, velocity, yaw, yaw_rate)

    def _set_attitude_target(self, link: MavlinkLink, msg) -> None:
        """PX4's type_mask semantics (mavlink_receiver.cpp): the attitude when it is not
        ignored, else the three body rates (all needed here); thrust is 0..1 either way."""
        mask = msg.type_mask
        if mask & mavlink.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE:
            self.unexpected += 1  # the reference autopilot has no "keep the last thrust"
            return
        if not math.isfinite(msg.thrust):
            self.malformed += 1
            return
        if mask & mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE:
            if mask & _RATES_IGNORED:
                self.unexpected += 1  # neither an attitude nor all three body rates
                return
            rates = np.array([msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate])
            if not np.isfinite(rates).all():
                self.malformed += 1
                return
            self.fc.set_offboard_rates(rates, msg.thrust)
            return
        q = np.array(msg.q, dtype=float)
        norm = float(np.linalg.norm(q))
        if not (math.isfinite(norm) and norm > 0.5):
            self.malformed += 1
            return
        self.fc.set_offboard_attitude(q / norm, msg.thrust)

    # ------------------------------------------------------------------ send
    def flush_events(self) -> None:
        """Status texts and mission progress go to every link."""
        fc = self.fc
        while fc.status_messages:
            severity, text = fc.status_messages.popleft()
            for link in self.links:
                link.send(mavlink.MAVLink_statustext_message(severity, text[:50].encode()))
        while fc.mission_events:
            kind, seq = fc.mission_events.popleft()
            for link in self.links:
                if kind == "reached":
                    link.send(mavlink.MAVLink_mission_item_reached_message(seq))
                else:
                    link.send(self._telemetry("MISSION_CURRENT"))

    def stream(self, time_us: int) -> None:
        """Send every message that is due at simulated time ``time_us``."""
        for link in self.links:
            for name, interval in link.intervals_us.items():
                if interval < 0 or time_us < link.next_send_us[name]:
                    continue
                link.next_send_us[name] = time_us + interval
                message = self._telemetry(name)
                if message is not None:
                    link.send(message)
        self.flush_events()

    def heartbeat(self) -> None:
        """A heartbeat outside the stream (before the simulator runs, PX4 is already seen)."""
        for link in self.links:
            link.send(self._telemetry("HEARTBEAT"))

    def _telemetry(self, name: str):
        fc = self.fc
        boot_ms = fc.time_us // 1000
        if name == "HEARTBEAT":
            base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            if fc.armed:
                base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
            status = mavlink.MAV_STATE_ACTIVE if fc.armed else mavlink.MAV_STATE_STANDBY
            if fc.failsafe:
                status = mavlink.MAV_STATE_CRITICAL
            return mavlink.MAVLink_heartbeat_message(
                mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, base,
                custom_mode(fc.nav_state), status, 3)  # fmt: skip
        if name == "SYS_STATUS":
            # The pre-arm check bit, as PX4 sets it: MAVSDK's ``is_armable`` reads it.
            present = mavlink.MAV_SYS_STATUS_PREARM_CHECK
            healthy = present if fc.armed or fc.preflight_failure() is None else 0
            for bit, key in zip(_SENSORS, _MONITOR_KEYS, strict=True):
                present |= bit if fc.monitors[key].last_time_us is not None else 0
                healthy |= bit if fc.monitors[key].healthy(fc.time_us) else 0
            return mavlink.MAVLink_sys_status_message(
                present, present, healthy, 0, 0, -1, -1, 0, self.malformed, 0, 0, 0, 0)  # fmt: skip
        if name == "EXTENDED_SYS_STATE":
            return mavlink.MAVLink_extended_sys_state_message(
                mavlink.MAV_VTOL_STATE_UNDEFINED, fc.landed_state())  # fmt: skip
        if name == "ATTITUDE":
            roll, pitch, yaw = euler_from_quat(fc.attitude.q)
            p, q, r = fc.attitude.rates_radps
            return mavlink.MAVLink_attitude_message(boot_ms, roll, pitch, yaw, p, q, r)
        if name == "MISSION_CURRENT":
            nav = fc.navigator
            return mavlink.MAVLink_mission_current_message(
                min(nav.mission_seq, max(len(nav.mission) - 1, 0)), len(nav.mission)
            )
        if fc.position.origin is None:
            return None
        x, y, z = fc.position.position_ned_m
        vx, vy, vz = fc.position.velocity_ned_mps
        if name == "LOCAL_POSITION_NED":
            return mavlink.MAVLink_local_position_ned_message(boot_ms, x, y, z, vx, vy, vz)
        lat, lon, alt = fc.global_position()
        if name == "GLOBAL_POSITION_INT":
            home_alt = fc.home[2] if fc.home else fc.position.origin[2]
            heading = math.degrees(euler_from_quat(fc.attitude.q)[2]) % 360.0
            return mavlink.MAVLink_global_position_int_message(
                boot_ms, round(lat * 1e7), round(lon * 1e7), round(alt * 1000),
                round((alt - home_alt) * 1000), _cm(vx), _cm(vy), _cm(vz),
                round(heading * 100) % 36000)  # fmt: skip
        if name == "HOME_POSITION" and fc.home is not None:
            hlat, hlon, halt = fc.home
            hx, hy, hz = fc.navigator.home_ned
            return mavlink.MAVLink_home_position_message(
                round(hlat * 1e7), round(hlon * 1e7), round(halt * 1000), hx, hy, hz,
                [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, fc.time_us)  # fmt: skip
        return None


def _param_id(raw) -> str:
    """A MAVLink param_id (16 chars, NUL padded) as text."""
    text = raw.decode("ascii") if isinstance(raw, bytes) else str(raw)
    return text.split("\x00", 1)[0]


def _cm(value_mps: float) -> int:
    """m/s → cm/s in int16, clamped (GLOBAL_POSITION_INT velocity fields)."""
    return max(-32768, min(32767, round(value_mps * 100)))
