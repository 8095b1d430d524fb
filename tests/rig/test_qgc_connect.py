"""QGroundControl's connect sequence, played with pymavlink on a real UDP socket against the
reference autopilot, and against PX4 SITL where a build is given, to show both answer alike.

What QGroundControl asks on connect (``src/Vehicle/InitialConnectStateMachine.cc`` and the
managers it calls), in order: AUTOPILOT_VERSION (REQUEST_MESSAGE to component 1), then
PROTOCOL_VERSION (without it QGC falls back to MAVLink 1), AVAILABLE_MODES (standard
modes), COMPONENT_METADATA and then COMPONENT_INFORMATION, the parameters
(PARAM_REQUEST_LIST; PX4 sends ``_HASH_CHECK`` first, QGC's cache key), the mission, the
geofence and the rally points (MISSION_REQUEST_LIST with mission_type 0, 1, 2, the last two
only with the MISSION_FENCE / MISSION_RALLY capabilities), and the home position.

PX4 v1.14 (the SITL build, probed by hand): every request is answered within a few ms; a
REQUEST_MESSAGE for a message it cannot send (AVAILABLE_MODES, an unknown id) is DENIED, an
unknown command UNSUPPORTED. Its component metadata points at files on its MAVLink FTP,
which the reference autopilot does not serve, so it DENIES those requests (QGC then uses
its own PX4 metadata).
"""

from __future__ import annotations

import socket
import struct
import time
import zlib
from dataclasses import dataclass, field

import pytest

from rig.autopilots.px4 import PX4_DIR_ENV, find_px4
from rig.autopilots.reference.params import Parameters
from rig.mavlink.px4_api import Ports, mavlink
from tests.rig.background_rig import RigInBackground, wait_until_bound

pytestmark = pytest.mark.closed_loop
#: An answer later than this (wall seconds) would be a QGC time-out and retry.
PROMPT_S = 0.5
PROTOCOL_VERSION_ID = 300  # not in pymavlink's common dialect any more
AVAILABLE_MODES_ID = 435
COMPONENT_METADATA_ID, COMPONENT_INFORMATION_ID = 397, 395
#: PX4 v1.14's AUTOPILOT_VERSION capability bits that the reference autopilot shares.
PX4_CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
)  # fmt: skip


class Qgc:
    """QGroundControl's side: system 255, component MISSIONPLANNER, one UDP socket."""

    def __init__(self, port: int, target_system: int) -> None:
        self.target_system = target_system
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.target = ("127.0.0.1", port)
        self.mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        self.heard: list = []

    def send(self, message) -> None:
        self.sock.sendto(message.pack(self.mav), self.target)

    def listen(self, until, timeout_s: float) -> list:
        """Messages from the vehicle until ``until(message)`` holds (that one included), or
        ``timeout_s`` wall seconds; each datagram parsed on its own."""
        deadline = time.monotonic() + timeout_s
        heard: list = []
        while time.monotonic() < deadline:
            try:
                data = self.sock.recv(65535)
            except TimeoutError:
                continue
            parser = mavlink.MAVLink(None)
            parser.robust_parsing = True
            for message in parser.parse_buffer(data) or []:
                if message.get_srcSystem() not in (self.target_system, 0):
                    continue  # another vehicle (0: pymavlink's undecoded frames say none)
                heard.append(message)
                if until(message):
                    self.heard.extend(heard)
                    return heard
        self.heard.extend(heard)
        return heard

    def request(self, command: int, *params: float) -> tuple[int | None, float, list]:
        """COMMAND_LONG to component 1: (ACK result or None, seconds to it, what came first)."""
        padded = [*params, *[0.0] * (7 - len(params))]
        start = time.monotonic()
        self.send(self.mav.command_long_encode(self.target_system, 1, command, 0, *padded))
        heard = self.listen(lambda m: m.get_type() == "COMMAND_ACK" and m.command == command, 2.0)
        ack = heard[-1] if heard and heard[-1].get_type() == "COMMAND_ACK" else None
        return (None if ack is None else ack.result), time.monotonic() - start, heard[:-1]


@dataclass
class Answers:
    """What the vehicle answered to each step of the sequence."""

    acks: dict[str, tuple[int | None, float]] = field(default_factory=dict)
    autopilot_version: object = None
    protocol_version: tuple[int, int, int] | None = None
    params: list = field(default_factory=list)
    mission_counts: dict[int, object] = field(default_factory=dict)
    home: object = None


def _first(messages: list, kind: str):
    return next((m for m in messages if m.get_type() == kind), None)


def _request_message(qgc: Qgc, answers: Answers, name: str, message_id: int) -> list:
    result, seconds, heard = qgc.request(mavlink.MAV_CMD_REQUEST_MESSAGE, message_id)
    answers.acks[name] = (result, seconds)
    return heard


def play_qgc_connect(qgc: Qgc) -> Answers:
    """QGroundControl's initial connect sequence, as it sends it."""
    answers = Answers()
    qgc.send(qgc.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                      0, 0, mavlink.MAV_STATE_ACTIVE))  # fmt: skip
    heartbeat = qgc.listen(lambda m: m.get_type() == "HEARTBEAT", 5.0)
    assert heartbeat, "no HEARTBEAT from the vehicle"
    assert heartbeat[-1].autopilot == mavlink.MAV_AUTOPILOT_PX4
    heard = _request_message(qgc, answers, "AUTOPILOT_VERSION",
                             mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)  # fmt: skip
    answers.autopilot_version = _first(heard, "AUTOPILOT_VERSION")
    heard = _request_message(qgc, answers, "PROTOCOL_VERSION", PROTOCOL_VERSION_ID)
    raw = _first(heard, f"UNKNOWN_{PROTOCOL_VERSION_ID}")
    if raw is not None:  # pymavlink's common dialect leaves it undecoded: the whole frame,
        frame = bytes(raw.data)  # whose payload MAVLink 2 cut after its last non-zero byte
        payload = frame[10 : 10 + frame[1]].ljust(6, b"\0")
        answers.protocol_version = struct.unpack_from("<HHH", payload)
    _request_message(qgc, answers, "AVAILABLE_MODES", AVAILABLE_MODES_ID)
    _request_message(qgc, answers, "COMPONENT_METADATA", COMPONENT_METADATA_ID)
    _request_message(qgc, answers, "COMPONENT_INFORMATION", COMPONENT_INFORMATION_ID)
    qgc.send(qgc.mav.param_request_list_encode(qgc.target_system, 1))
    names: set[str] = set()

    def all_parameters(message) -> bool:
        """Until every name came, counted by the first answer's param_count (plus the hash)."""
        if message.get_type() == "PARAM_VALUE":
            answers.params.append(message)
            names.add(message.param_id)
        return bool(answers.params) and len(names) > answers.params[0].param_count

    qgc.listen(all_parameters, 30.0)
    for kind in (mavlink.MAV_MISSION_TYPE_MISSION, mavlink.MAV_MISSION_TYPE_FENCE,
                 mavlink.MAV_MISSION_TYPE_RALLY):  # fmt: skip
        qgc.send(qgc.mav.mission_request_list_encode(qgc.target_system, 1, kind))
        heard = qgc.listen(lambda m: m.get_type() in ("MISSION_COUNT", "MISSION_ACK"), 2.0)
        answers.mission_counts[kind] = heard[-1] if heard else None
    heard = _request_message(qgc, answers, "HOME_POSITION", mavlink.MAVLINK_MSG_ID_HOME_POSITION)
    answers.home = _first(heard, "HOME_POSITION")
    result, seconds, _ = qgc.request(31000)  # MAV_CMD_USER_1: nobody implements it
    answers.acks["MAV_CMD_USER_1"] = (result, seconds)
    return answers


def qgc_parameter_hash(params: list) -> int:
    """QGroundControl's cache CRC (``ParameterManager::_tryCacheHashLoad``): CRC-32 without
    inversion over each name and its 4 value bytes, names in order."""
    crc = 0
    for value in sorted(params, key=lambda m: m.param_id):
        data = value.param_id.encode() + struct.pack("<f", value.param_value)
        crc = zlib.crc32(data, crc ^ 0xFFFFFFFF) ^ 0xFFFFFFFF
    return crc


def check_as_px4_answers(answers: Answers, parameter_count: int,
                         release: tuple[int, int] = (1, 14)) -> None:  # fmt: skip
    """The shape of PX4's answers, step by step (the reference autopilot answers as v1.14)."""
    for name, (result, seconds) in answers.acks.items():
        assert result is not None, f"{name}: no COMMAND_ACK"
        assert seconds < PROMPT_S, (name, seconds)
    accepted = mavlink.MAV_RESULT_ACCEPTED
    assert answers.acks["AUTOPILOT_VERSION"][0] == accepted
    version = answers.autopilot_version
    assert version.capabilities & PX4_CAPABILITIES == PX4_CAPABILITIES
    assert version.flight_sw_version >> 16 == release[0] << 8 | release[1]
    assert answers.acks["PROTOCOL_VERSION"][0] == accepted
    version_now, version_min, version_max = answers.protocol_version
    assert (version_now, version_min) == (200, 100)
    assert version_max == 200 if release < (1, 15) else version_max >= 200
    modes = mavlink.MAV_RESULT_DENIED if release < (1, 15) else accepted  # came with v1.15
    assert answers.acks["AVAILABLE_MODES"][0] == modes
    for name in ("COMPONENT_METADATA", "COMPONENT_INFORMATION"):
        assert answers.acks[name][0] in (accepted, mavlink.MAV_RESULT_DENIED)
    first = answers.params[0]
    assert (first.param_id, first.param_type) == ("_HASH_CHECK", mavlink.MAV_PARAM_TYPE_UINT32)
    assert (first.param_index, first.param_count) == (65535, parameter_count)
    values = answers.params[1:]
    assert sorted(m.param_index for m in values) == list(range(parameter_count))
    assert {m.param_count for m in values} == {parameter_count}
    for kind, count in answers.mission_counts.items():
        assert count is not None, f"mission type {kind}: no answer"
        assert count.get_type() == "MISSION_COUNT", (kind, count)
        assert (count.count, count.mission_type) == (0, kind)
    assert answers.acks["HOME_POSITION"][0] == accepted
    assert answers.home is not None
    assert answers.acks["MAV_CMD_USER_1"][0] == mavlink.MAV_RESULT_UNSUPPORTED


def _connect(tmp_path, instance: int, speed: float, **options) -> Answers:
    """The rig in the background; QGC connects once the vehicle has its home position."""
    ports = Ports(instance)
    rig = RigInBackground(tmp_path, instance, duration_s=25.0, speed=speed, **options)
    wait_until_bound(ports.gcs_local_udp, 60.0)
    qgc = Qgc(ports.gcs_local_udp, ports.system_id)
    qgc.send(qgc.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                      0, 0, mavlink.MAV_STATE_ACTIVE))  # fmt: skip
    assert qgc.listen(lambda m: m.get_type() == "HOME_POSITION", 20.0), "no home position"
    answers = play_qgc_connect(qgc)
    qgc.sock.close()
    rig.finish(timeout_s=60)
    return answers


def test_reference_autopilot_answers_qgc_connect_as_px4(tmp_path, free_instance):
    """Every step answered promptly and shaped as PX4 v1.14 answers it; the parameter hash
    is the CRC QGroundControl computes over the values it received, so its cache works."""
    parameter_count = len(Parameters())
    answers = _connect(tmp_path, free_instance(), speed=2.0)
    check_as_px4_answers(answers, parameter_count)
    for name in ("COMPONENT_METADATA", "COMPONENT_INFORMATION"):
        assert answers.acks[name][0] == mavlink.MAV_RESULT_DENIED  # no FTP to serve them
    hash_bits = struct.unpack("<I", struct.pack("<f", answers.params[0].param_value))[0]
    assert hash_bits == qgc_parameter_hash(answers.params[1:])


def test_px4_answers_qgc_connect_alike(tmp_path, free_instance):
    """The same sequence and checks against PX4 SITL through the rig."""
    build = find_px4()
    if build is None:
        pytest.skip(f"no PX4 SITL build: set {PX4_DIR_ENV} (CI points it at ../shared/px4_sitl)")
    answers = _connect(tmp_path, free_instance(), speed=1.0, autopilot="px4",
                       px4_dir=build.root)  # fmt: skip
    check_as_px4_answers(answers, answers.params[0].param_count, build.release)
