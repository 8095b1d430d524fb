"""Every MAVLink input path over real loopback sockets, fed fuzzed frames between good ones.

- the simulator link (TCP 4560+i), where the autopilot's HIL_ACTUATOR_CONTROLS arrive:
  garbage before a frame's answer never costs the answer, and a NaN motor command is one
  line (:class:`AutopilotProtocolError`), never a traceback;
- the rig's onboard link (UDP 14280+i), which hears the autopilot's telemetry;
- the reference autopilot's ground-station and API ports (UDP 18570+i, 14580+i): whatever
  a station sends, the autopilot goes on answering a good command after it.
"""

from __future__ import annotations

import atexit
import functools
import socket

from hypothesis import given

from quad_model.environment import PX4_DEFAULT_HOME
from rig.autopilots.reference.flight_controller import FlightController
from rig.autopilots.reference.gcs import GroundStation, MavlinkLink
from rig.errors import AutopilotProtocolError
from rig.mavlink.ground_link import GroundLink
from rig.mavlink.px4_api import LOCKSTEP_FLAG, Ports, mavlink
from rig.mavlink.simulator_link import LinkTimeouts, SimulatorLink
from tests.fuzz.inputs import mavlink_datagrams, one_line
from tests.instances import free_test_instance

_PACKER = mavlink.MAVLink(None, 1, 1)


class _SimulatorPeer:
    """A simulator link with a connected autopilot socket, kept across examples."""

    def __init__(self) -> None:
        ports = Ports(free_test_instance())
        self.link = SimulatorLink(ports, LinkTimeouts(connect_s=5, answer_s=2), motors=4)
        self.autopilot = socket.create_connection(("127.0.0.1", ports.simulator_tcp))
        self.link.accept(answers_every_frame=True)
        self.time_us = 0
        atexit.register(self.autopilot.close)
        atexit.register(self.link.close)


@functools.cache
def _simulator_peer() -> _SimulatorPeer:
    return _SimulatorPeer()


@given(mavlink_datagrams())
def test_garbage_before_an_answer_on_the_simulator_link(data: bytes) -> None:
    peer = _simulator_peer()
    peer.time_us += 4000
    answer = _PACKER.hil_actuator_controls_encode(
        peer.time_us, [0.5] * 4 + [0.0] * 12, mavlink.MAV_MODE_FLAG_SAFETY_ARMED, LOCKSTEP_FLAG
    ).pack(_PACKER)
    # The garbage ends with whole frames so TCP's byte stream cannot merge it into the answer.
    peer.autopilot.sendall(data + b"\x00" * 280 + answer)
    try:
        controls = peer.link.exchange(peer.time_us, [])
    except AutopilotProtocolError as error:  # e.g. a fuzzed answer with a NaN motor command
        one_line(error)
        return
    assert controls is not None
    assert controls.time_us >= peer.time_us


@functools.cache
def _ground_link() -> tuple[GroundLink, socket.socket]:
    ports = Ports(free_test_instance())
    link = GroundLink(ports, PX4_DEFAULT_HOME)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.connect(("127.0.0.1", ports.onboard_remote_udp))
    atexit.register(sender.close)
    atexit.register(link.close)
    return link, sender


@given(mavlink_datagrams())
def test_garbage_on_the_rigs_onboard_link(data: bytes) -> None:
    link, sender = _ground_link()
    sender.send(data)
    assert link.poll(0.0) is None  # nothing pending: drained, counted, no exception


@functools.cache
def _reference_autopilot() -> tuple[GroundStation, MavlinkLink, socket.socket]:
    ports = Ports(free_test_instance())
    link = MavlinkLink("gcs", ports.gcs_local_udp, 0, 1)
    station = GroundStation(FlightController(), [link])
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.bind(("127.0.0.1", 0))
    sender.connect(("127.0.0.1", ports.gcs_local_udp))
    sender.settimeout(1.0)
    link.peer = sender.getsockname()
    atexit.register(sender.close)
    atexit.register(link.close)
    return station, link, sender


@given(mavlink_datagrams())
def test_garbage_then_a_command_on_the_autopilots_ground_port(data: bytes) -> None:
    station, link, sender = _reference_autopilot()
    ping = mavlink.MAVLink_command_long_message(
        1, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
        0, 0, 0, 0, 0, 0,
    ).pack(mavlink.MAVLink(None, 255, 190))  # fmt: skip
    sender.send(data)
    sender.send(ping)
    for message, address in link.receive():
        station.handle(link, message, address)
    parser = mavlink.MAVLink(None)
    acked = False
    while not acked:
        for message in parser.parse_buffer(sender.recv(65535)) or ():
            acked |= (message.get_type() == "COMMAND_ACK"
                      and message.command == mavlink.MAV_CMD_REQUEST_MESSAGE)  # fmt: skip
