"""The ground-station side: MAVLink over UDP as PX4 SITL serves it.

Three links per instance (``Ports``), as PX4 SITL opens them: the GCS link binds 18570+i
and talks to 14550 (QGroundControl, MAVProxy), the API link binds 14580+i and talks to
14540+i (MAVSDK, scripts), the onboard link binds 14280+i and talks to 14030+i (the rig's
scenario commands, as a companion computer's). Answers go to the sender of the request;
telemetry to whoever last talked to the link and to every other station heard lately, so a
second sender (a fuzzer, a second ground station) cannot take a ground station's telemetry
away. Telemetry is paced by simulated time (the autopilot's only clock), so a run's messages
do not depend on the wall clock.

Protocols follow PX4's ``mavlink`` module and MAVLink's ``common.xml``: commands with
COMMAND_ACK, the mission protocol (upload and download, MISSION_CURRENT and
MISSION_ITEM_REACHED; empty geofence and rally lists), the parameter protocol with PX4's
bytewise int32 encoding and its ``_HASH_CHECK``, MAVLink FTP refused as PX4 refuses a
missing file, and offboard set-points. Malformed or unexpected messages are counted and
ignored; malformed ones are reported on stderr, at most once a minute.
"""

from __future__ import annotations

import contextlib
import math
import socket
import struct
import sys
import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from quad_model.frames import euler_from_quat
from rig.autopilots.reference.flight_controller import CommandResult, FlightController
from rig.autopilots.reference.manual import sticks_from_manual_control
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
#: PX4 v1.14's AUTOPILOT_VERSION.capabilities less what the reference autopilot lacks: MAVLink
#: FTP, MISSION_ITEM (float) uploads, flight termination, the reserved bit.
_CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
)  # fmt: skip
#: AUTOPILOT_VERSION.flight_sw_version: the PX4 release whose protocol it speaks, 1.14.0 (a
#: ground station picks PX4's parameter metadata and features by it).
_FLIGHT_SW_VERSION = (1 << 24) | (14 << 16) | mavlink.FIRMWARE_VERSION_TYPE_DEV
#: The parameter set's hash (QGroundControl's cache key), sent first, as PX4 sends it.
HASH_PARAM = "_HASH_CHECK"
_NO_INDEX = 65535  # PARAM_VALUE.param_index of the hash: PX4's -1 in the uint16 field
#: A link reads at most this many datagrams per call, so a flood cannot starve the simulator.
MAX_DATAGRAMS_PER_POLL = 64
#: Besides the last sender, stations heard within this many (wall) seconds get telemetry.
PEER_TIMEOUT_S, MAX_PEERS = 5.0, 4
#: Malformed input is reported on stderr at most this often (wall seconds).
GARBAGE_REPORT_S = 60.0
#: MAVLink FTP (``FILE_TRANSFER_PROTOCOL.payload``): header, opcodes and error codes.
#: The header: seq, session, opcode, size, req_opcode, burst_complete, padding, offset.
_FTP_HEADER = struct.Struct("<HBBBBBBI")
_FTP_PAYLOAD_LEN = 251
_FTP_ACK, _FTP_NAK = 128, 129
_FTP_RESET_SESSIONS = 2
_FTP_SESSION_OPS = {1, 5, 7, 15}  # terminate, read, write, burst read
_FTP_PATH_OPS = {3, 4, 6, 8, 9, 10, 11, 12, 13, 14, 16}  # list, open, create, remove, ...
_FTP_ERR_INVALID_SESSION, _FTP_ERR_UNKNOWN_COMMAND, _FTP_ERR_FILE_NOT_FOUND = 4, 7, 10
#: Commands that ask for one message, as PX4 maps them onto REQUEST_MESSAGE.
_REQUESTS_OF_ONE_MESSAGE = {
    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
    mavlink.MAV_CMD_REQUEST_PROTOCOL_VERSION: 300,  # PROTOCOL_VERSION
    mavlink.MAV_CMD_GET_HOME_POSITION: mavlink.MAVLINK_MSG_ID_HOME_POSITION,
}
#: MISSION_CLEAR_ALL.mission_type: every list.
_MISSION_TYPE_ALL = 255
_MISSION_TYPES = (mavlink.MAV_MISSION_TYPE_MISSION, mavlink.MAV_MISSION_TYPE_FENCE,
                  mavlink.MAV_MISSION_TYPE_RALLY)  # fmt: skip

Address = tuple[str, int]


class ProtocolVersion(mavlink.MAVLink_message):
    """PROTOCOL_VERSION (id 300, CRC extra 217), which pymavlink's ``common`` dialect no
    longer has: QGroundControl asks for it on connect and falls back to MAVLink 1 when it
    gets no answer. MAVLink 2 (200), down to MAVLink 1 (100); spec hashes unknown (zero)."""

    MESSAGE_ID, CRC_EXTRA = 300, 217

    def __init__(self) -> None:
        super().__init__(self.MESSAGE_ID, "PROTOCOL_VERSION")
        self.version, self.min_version, self.max_version = 200, 100, 200

    def pack(self, mav: mavlink.MAVLink, force_mavlink1: bool = False) -> bytes:
        payload = struct.pack("<HHH8s8s", self.version, self.min_version, self.max_version,
                              bytes(8), bytes(8))  # fmt: skip
        return self._pack(mav, self.CRC_EXTRA, payload, force_mavlink1)


@dataclass
class _Upload:
    """A mission upload in progress on one link."""

    count: int
    peer: tuple[int, int]  # the uploader's system and component ids
    address: Address | None  # where the uploader listens (None: the link's last sender)
    items: list[MissionItem] = field(default_factory=list)
    last_request_s: float = 0.0
    retries: int = 0


class MavlinkLink:
    """One UDP endpoint: a bound socket, the stations it serves, and its own stream rates."""

    def __init__(self, name: str, bind_port: int, remote_port: int, system_id: int) -> None:
        self.name = name
        self.port = bind_port
        self.system_id = system_id
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", bind_port))
        self.sock.setblocking(False)
        self.peer: Address = ("127.0.0.1", remote_port)  # the last station that talked
        self._heard: dict[Address, float] = {}  # station → when it last talked (monotonic)
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=1)
        self._parser = _parser()
        self.intervals_us = dict(DEFAULT_INTERVALS_US)
        self.next_send_us = dict.fromkeys(DEFAULT_INTERVALS_US, 0)
        self.upload: _Upload | None = None

    def receive(self) -> list[tuple[object, Address]]:
        """Messages waiting on the socket with their senders (bad data as ``BAD_DATA``).

        Each datagram is parsed on its own: a frame cut off at its end is bad data, not the
        start of the next datagram's frame (which would swallow a good command after it).
        Only a valid message addressed to this system makes its sender a station served.
        """
        received: list[tuple[object, Address]] = []
        for _ in range(MAX_DATAGRAMS_PER_POLL):
            try:
                data, address = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # e.g. ICMP port unreachable reported on a later call
                continue
            messages = self._parse(data)
            if any(_addressed_to(message, self.system_id) for message in messages):
                self._hear(address)
            received.extend((message, address) for message in messages)
        return received

    def _parse(self, data: bytes) -> list:
        messages = self._parser.parse_buffer(data) or []
        if self._parser.buf_len():
            rest = self._parser.buf[self._parser.buf_index :]
            messages.append(mavlink.MAVLink_bad_data(rest, "frame cut off by the datagram's end"))
            self._parser = _parser()
        return messages

    def _hear(self, address: Address) -> None:
        now = time.monotonic()
        self.peer = address
        self._heard[address] = now
        for station, heard in list(self._heard.items()):
            if now - heard > PEER_TIMEOUT_S:
                del self._heard[station]
        while len(self._heard) > MAX_PEERS:
            del self._heard[min(self._heard, key=self._heard.__getitem__)]

    def stations(self) -> list[Address]:
        """Where telemetry goes: the last sender, and every other station heard lately."""
        now = time.monotonic()
        others = [a for a, t in self._heard.items() if a != self.peer and now - t <= PEER_TIMEOUT_S]
        return [self.peer, *others]

    def send(self, message: mavlink.MAVLink_message, to: Address | None = None) -> None:
        """To ``to`` (an answer), else as telemetry to :meth:`stations`."""
        data = message.pack(self.mav)
        for address in [to] if to is not None else self.stations():
            # nobody listening (yet) is fine: UDP telemetry is fire-and-forget, as in PX4
            with contextlib.suppress(OSError):
                self.sock.sendto(data, address)

    def close(self) -> None:
        self.sock.close()


def _parser() -> mavlink.MAVLink:
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    return parser


def _addressed_to(message: mavlink.MAVLink_message, system_id: int) -> bool:
    """Valid, and for this system (or for every system, or with no target at all)."""
    if message.get_type() == "BAD_DATA":
        return False
    return getattr(message, "target_system", 0) in (0, system_id)


class GroundStation:
    """Serves the flight controller to ground stations on one or more links."""

    def __init__(self, controller: FlightController, links: list[MavlinkLink]) -> None:
        self.fc = controller
        self.links = links
        self.malformed = 0
        self.unexpected = 0
        self._reply_to: Address | None = None  # the sender of the message being handled
        self._garbage_reported_s: float | None = None
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
            "MANUAL_CONTROL": self._manual_control,
            "FILE_TRANSFER_PROTOCOL": self._file_transfer,
        }

    # ------------------------------------------------------------------ receive
    def handle(
        self,
        link: MavlinkLink,
        message: mavlink.MAVLink_message,
        sender: Address | None = None,
    ) -> None:
        """Dispatch one message; anything malformed or unknown is counted, never raised.
        Answers go to ``sender`` (None: the link's last sender)."""
        kind = message.get_type()
        if kind == "BAD_DATA":
            self._malformed(link, sender)
            return
        handler = self._handlers.get(kind)
        if handler is None or not _addressed_to(message, int(self.fc.params["MAV_SYS_ID"])):
            self.unexpected += 1
            return
        self._reply_to = sender
        try:
            handler(link, message)
        except (ValueError, TypeError, OverflowError, struct.error, UnicodeError):
            self._malformed(link, sender)  # e.g. NaN where an integer is needed
        finally:
            self._reply_to = None
        self.flush_events()

    def _reply(self, link: MavlinkLink, message: mavlink.MAVLink_message) -> None:
        link.send(message, self._reply_to)

    def _malformed(self, link: MavlinkLink | None, sender: Address | None) -> None:
        """Count it; say so on stderr once, then at most every GARBAGE_REPORT_S seconds, so a
        flood leaves one line in the console instead of one per datagram."""
        self.malformed += 1
        now = time.monotonic()
        last = self._garbage_reported_s
        if last is not None and now - last < GARBAGE_REPORT_S:
            return
        self._garbage_reported_s = now
        where = f" on the {link.name} link (UDP {link.port})" if link is not None else ""
        source = f" from {sender[0]}:{sender[1]}" if sender is not None else ""
        print(f"rig.autopilots.reference: ignoring malformed MAVLink{where}{source} (bytes that "
              f"are not MAVLink, bad CRC, cut-off frames or invalid fields): {self.malformed} so "
              f"far, counted in SYS_STATUS.errors_comm; said again at most once a minute",
              file=sys.stderr, flush=True)  # fmt: skip

    # ------------------------------------------------------------------ commands
    def _command_long(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                  msg.param7)  # fmt: skip
        self._command(link, msg, msg.command, params)

    def _command_int(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x * 1e-7, msg.y * 1e-7,
                  msg.z)  # fmt: skip
        self._command(link, msg, msg.command, params)

    def _command(
        self, link: MavlinkLink, msg: mavlink.MAVLink_message, command: int, p: tuple[float, ...]
    ) -> None:
        try:
            result = self._run_command(link, command, p)
        except (ValueError, OverflowError):  # NaN or ∞ where a mode or index was needed
            self._malformed(link, self._reply_to)
            result = CommandResult(mavlink.MAV_RESULT_DENIED)
        self.flush_events()  # a refusal's reason goes out before its ACK
        self._reply(link, mavlink.MAVLink_command_ack_message(
            command, result.result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()))  # fmt: skip

    def _run_command(self, link: MavlinkLink, command: int, p: tuple[float, ...]) -> CommandResult:
        fc = self.fc
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] not in (0.0, 1.0):  # PX4's commander: "Unsupported ARM_DISARM param"
                return CommandResult(mavlink.MAV_RESULT_UNSUPPORTED)
            force = round(p[1]) == 21196 if math.isfinite(p[1]) else False
            result = fc.arm(force) if p[0] == 1.0 else fc.disarm(force)
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
        elif command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            result = self._send_once(link, int(p[0]))
        elif command in _REQUESTS_OF_ONE_MESSAGE:
            result = self._send_once(link, _REQUESTS_OF_ONE_MESSAGE[command])
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
            return self.fc.refuse(f"Mode {int(p[1])}/{int(p[2])} not available")
        return self.fc.set_mode(nav_state)

    def _set_interval(
        self, link: MavlinkLink, message_id: int, interval_us: float
    ) -> CommandResult:
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
        """The message, to the requester, before the ACK; DENIED when there is none to send
        (unknown, or no data yet such as home before a position fix), as PX4 answers."""
        if message_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            message = mavlink.MAVLink_autopilot_version_message(
                _CAPABILITIES, _FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0,
                self.fc.params["MAV_SYS_ID"])  # fmt: skip
        elif message_id == ProtocolVersion.MESSAGE_ID:
            message = ProtocolVersion()
        else:
            name = _NAMES_BY_ID.get(message_id)
            message = self._telemetry(name) if name else None
        if message is None:
            return CommandResult(mavlink.MAV_RESULT_DENIED)
        self._reply(link, message)
        return CommandResult(mavlink.MAV_RESULT_ACCEPTED)

    # ------------------------------------------------------------------ parameters
    def _param_value(self, name: str) -> mavlink.MAVLink_param_value_message:
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

    def _param_request_list(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        """The hash first (QGroundControl loads its cache when it matches), then each one."""
        params = self.fc.params
        hash_bits = struct.unpack("<f", struct.pack("<I", self.parameter_hash()))[0]
        self._reply(link, mavlink.MAVLink_param_value_message(
            HASH_PARAM.encode(), hash_bits, mavlink.MAV_PARAM_TYPE_UINT32, len(params),
            _NO_INDEX))  # fmt: skip
        for name in params:
            self._reply(link, self._param_value(name))

    def parameter_hash(self) -> int:
        """PX4's ``param_hash_check`` as QGroundControl recomputes it from its cache: CRC-32
        (no pre- or post-inversion) over each name and its 4 value bytes, in name order."""
        crc = 0
        params = self.fc.params
        for name in sorted(params):
            kind = "<i" if params.spec(name).is_int else "<f"
            data = name.encode() + struct.pack(kind, params[name])
            crc = zlib.crc32(data, crc ^ 0xFFFFFFFF) ^ 0xFFFFFFFF
        return crc

    def _param_request_read(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        try:
            name = (self.fc.params.name_at(msg.param_index) if msg.param_index >= 0
                    else _param_id(msg.param_id))  # fmt: skip
            self._reply(link, self._param_value(name))
        except ParameterError as error:
            self.fc.notify(mavlink.MAV_SEVERITY_WARNING, str(error))

    def _param_set(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        name = _param_id(msg.param_id)
        if name == HASH_PARAM:
            return  # QGroundControl's "cache matched, stop": the list is already sent
        value = msg.param_value
        if msg.param_type == mavlink.MAV_PARAM_TYPE_INT32:
            value = struct.unpack("<i", struct.pack("<f", value))[0]
        try:
            self.fc.set_parameter(name, value)
        except ParameterError as error:
            self.fc.notify(mavlink.MAV_SEVERITY_WARNING, str(error))
            if name not in self.fc.params:
                return
        self._reply(link, self._param_value(name))  # the value it holds now, as PX4 answers

    # ------------------------------------------------------------------ missions
    def _mission_count(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        """An upload. Geofence and rally lists stay empty: clearing them is accepted, items
        are refused with a reason (there is no geofence or rally point to fly)."""
        kind = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if kind in (mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY):
            if msg.count:
                self.fc.notify(mavlink.MAV_SEVERITY_WARNING,
                               "Geofence and rally points are not supported")  # fmt: skip
                self.flush_events()
            verdict = mavlink.MAV_MISSION_UNSUPPORTED if msg.count else mavlink.MAV_MISSION_ACCEPTED
            self._mission_ack(link, msg, verdict, kind)
            return
        if kind != mavlink.MAV_MISSION_TYPE_MISSION:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_UNSUPPORTED, kind)
            return
        if msg.count == 0:
            self.fc.set_mission([])
            self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED)
            return
        link.upload = upload = _Upload(msg.count, (msg.get_srcSystem(), msg.get_srcComponent()),
                                       self._reply_to)  # fmt: skip
        self._request_item(link, upload)

    def _request_item(self, link: MavlinkLink, upload: _Upload) -> None:
        """Ask ``link``'s peer for the next item of ``upload`` (the link's upload)."""
        upload.last_request_s = time.monotonic()
        request = mavlink.MAVLink_mission_request_int_message(
            *upload.peer, len(upload.items), mavlink.MAV_MISSION_TYPE_MISSION)  # fmt: skip
        link.send(request, upload.address)

    def _mission_item_int(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        upload = link.upload
        if upload is None or msg.mission_type != mavlink.MAV_MISSION_TYPE_MISSION:
            self.unexpected += 1
            return
        if msg.seq != len(upload.items):  # a duplicate or out of order: ask again
            self._request_item(link, upload)
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
            self._request_item(link, upload)
            return
        link.upload = None
        self.fc.set_mission(upload.items)
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED)
        link.send(self._telemetry("MISSION_CURRENT"))

    def _mission_ack(self, link: MavlinkLink, msg: mavlink.MAVLink_message, result: int,
                     kind: int = mavlink.MAV_MISSION_TYPE_MISSION) -> None:  # fmt: skip
        self._reply(link, mavlink.MAVLink_mission_ack_message(
            msg.get_srcSystem(), msg.get_srcComponent(), result, kind))  # fmt: skip

    def _mission_request_list(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        """The mission's length; the geofence and rally lists are empty (PX4 with none)."""
        kind = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if kind not in _MISSION_TYPES:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_UNSUPPORTED, kind)
            return
        count = len(self.fc.navigator.mission) if kind == mavlink.MAV_MISSION_TYPE_MISSION else 0
        self._reply(link, mavlink.MAVLink_mission_count_message(
            msg.get_srcSystem(), msg.get_srcComponent(), count, kind))  # fmt: skip

    def _mission_request(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        kind = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        mission = self.fc.navigator.mission if kind == mavlink.MAV_MISSION_TYPE_MISSION else []
        if not 0 <= msg.seq < len(mission):
            self._mission_ack(link, msg, mavlink.MAV_MISSION_INVALID_SEQUENCE, kind)
            return
        i = mission[msg.seq]
        self._reply(link, mavlink.MAVLink_mission_item_int_message(
            msg.get_srcSystem(), msg.get_srcComponent(), i.seq, i.frame, i.command,
            int(i.seq == self.fc.navigator.mission_seq), i.autocontinue, i.param1, i.param2,
            i.param3, i.param4, i.x, i.y, i.z, mavlink.MAV_MISSION_TYPE_MISSION))  # fmt: skip

    def _mission_clear_all(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        """Clears the mission (type MISSION or ALL); the other lists are empty already."""
        kind = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if kind in (mavlink.MAV_MISSION_TYPE_MISSION, _MISSION_TYPE_ALL):
            self.fc.set_mission([])
        elif kind not in _MISSION_TYPES:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_UNSUPPORTED, kind)
            return
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED, kind)

    def _mission_set_current(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
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
            self._request_item(link, upload)

    # ------------------------------------------------------------------ file transfer
    def _file_transfer(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        """MAVLink FTP answered as by a PX4 without the file: a NAK at once, never silence, so
        MAVProxy and QGroundControl fall back to the parameter protocol without a time-out.
        There is no file system: every path is missing (PX4's answer to MAVProxy's
        ``@PARAM/param.pck``), no session is open, a session reset is acknowledged."""
        request = bytes(msg.payload)
        seq, session, opcode = _FTP_HEADER.unpack_from(request)[:3]
        if opcode in (_FTP_ACK, _FTP_NAK):
            self.unexpected += 1  # an answer: nothing was asked
            return
        if opcode == _FTP_RESET_SESSIONS:
            reply, data = _FTP_ACK, b""
        elif opcode in _FTP_PATH_OPS:
            reply, data = _FTP_NAK, bytes([_FTP_ERR_FILE_NOT_FOUND])
        elif opcode in _FTP_SESSION_OPS:
            reply, data = _FTP_NAK, bytes([_FTP_ERR_INVALID_SESSION])
        else:
            reply, data = _FTP_NAK, bytes([_FTP_ERR_UNKNOWN_COMMAND])
        answer = _FTP_HEADER.pack((seq + 1) & 0xFFFF, session, reply, len(data), opcode, 0, 0, 0)
        payload = (answer + data).ljust(_FTP_PAYLOAD_LEN, b"\0")
        self._reply(link, mavlink.MAVLink_file_transfer_protocol_message(
            0, msg.get_srcSystem(), msg.get_srcComponent(), list(payload)))  # fmt: skip

    # ------------------------------------------------------------------ offboard
    def _set_position_target(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
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

    def _manual_control(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
        """A pilot's sticks (PX4 ignores those addressed to another system)."""
        if msg.target != int(self.fc.params["MAV_SYS_ID"]):
            return
        self.fc.set_sticks(sticks_from_manual_control(msg.x, msg.y, msg.z, msg.r, self.fc.time_us))

    def _set_attitude_target(self, link: MavlinkLink, msg: mavlink.MAVLink_message) -> None:
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

    def _telemetry(self, name: str) -> mavlink.MAVLink_message | None:
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
            # The pre-arm check bit, as PX4 sets it: MAVSDK's ``is_armable`` reads it. The
            # geofence is absent but healthy (nothing breached): PX4 v1.14 leaves that bit
            # clear, which MAVProxy announces as "fence breach" at connect.
            present = mavlink.MAV_SYS_STATUS_PREARM_CHECK
            healthy = present if fc.armed or fc.preflight_failure() is None else 0
            healthy |= mavlink.MAV_SYS_STATUS_GEOFENCE
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
        if fc.position.origin is None and not fc.position_valid():
            return None
        x, y, z = fc.position.position_ned_m
        vx, vy, vz = fc.position.velocity_ned_mps
        if name == "LOCAL_POSITION_NED":
            return mavlink.MAVLink_local_position_ned_message(boot_ms, x, y, z, vx, vy, vz)
        if fc.position.origin is None:  # flying on optical flow: no global position
            return None
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


def _param_id(raw: str | bytes) -> str:
    """A MAVLink param_id (16 chars, NUL padded) as text."""
    text = raw.decode("ascii") if isinstance(raw, bytes) else str(raw)
    return text.split("\x00", 1)[0]


def _cm(value_mps: float) -> int:
    """m/s → cm/s in int16, clamped (GLOBAL_POSITION_INT velocity fields)."""
    return max(-32768, min(32767, round(value_mps * 100)))
