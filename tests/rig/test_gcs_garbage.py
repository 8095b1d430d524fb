"""A ground station that sends garbage cannot disturb the run.

While a pymavlink ground station flies the reference autopilot (arm, take-off, land) on
its GCS link, a second sender floods both ground-station ports (18570+i and 14580+i) with
random bytes, bytes that start like a MAVLink frame (0xFD, 0xFE), valid frames with a bad
CRC, frames cut off by the datagram's end, and valid messages with nonsense fields. Every
command of the flight is acknowledged at its first sending, the flight goes on, and the
autopilot says so in one line on its console, not one per datagram.

An older run lost about one command in three under such a flood: the autopilot parsed its
UDP input as one byte stream, so a frame cut off at the end of a garbage datagram swallowed
the start of the next datagram, the ground station's command. Each datagram is parsed on
its own now (first test, no rig needed).
"""

from __future__ import annotations

import math
import socket
import threading
import time

import numpy as np
import pytest
import pyulog

from rig.autopilots.reference.gcs import MavlinkLink
from rig.mavlink.px4_api import Ports, mavlink
from tests.rig.autopilot.gcs_client import GcsClient
from tests.rig.background_rig import RigInBackground, wait_until_bound

#: Datagrams per second on each port: well past any ground station's rate, while the
#: autopilot's socket buffers never fill (a kernel drop would lose commands at random).
FLOOD_PER_PORT_HZ = 250
ACK_WAIT_S = 1.0
GARBAGE_LINE = "ignoring malformed MAVLink"


class Flood:
    """A thread that sends seeded garbage to the given ports until stopped."""

    def __init__(self, ports: list[int], system_id: int, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.mav = mavlink.MAVLink(None, srcSystem=77, srcComponent=1)
        self.ports = ports
        self.system_id = system_id
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> int:
        self._stop.set()
        self._thread.join(5)
        self.sock.close()
        return self.sent

    def _run(self) -> None:
        period = 1.0 / FLOOD_PER_PORT_HZ
        while not self._stop.wait(period):
            for port in self.ports:
                self.sock.sendto(self.datagram(), ("127.0.0.1", port))
                self.sent += 1

    def datagram(self) -> bytes:
        """One of the five kinds of garbage, at random."""
        rng = self.rng
        kind = int(rng.integers(5))
        if kind == 0:
            return rng.bytes(int(rng.integers(1, 300)))
        if kind == 1:
            magic = bytes([int(rng.choice([0xFD, 0xFE]))])
            return magic + rng.bytes(int(rng.integers(0, 280)))
        frame = bytearray(self.nonsense().pack(self.mav))
        if kind == 2:  # a bad CRC
            frame[-1 - int(rng.integers(2))] ^= 1 + int(rng.integers(255))
            return bytes(frame)
        if kind == 3:  # cut off
            return bytes(frame[: int(rng.integers(1, len(frame)))])
        return bytes(frame)

    def nonsense(self):
        """A valid message whose fields make no sense (none that a real pilot would send:
        no arm/disarm, mode or mission change that would be a command after all)."""
        rng, mav, target = self.rng, self.mav, self.system_id
        nan = math.nan
        choices = (
            lambda: mav.command_long_encode(target, 1, int(rng.integers(30000, 40000)), 0,
                                            *rng.normal(size=7)),
            lambda: mav.command_long_encode(target, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM,
                                            0, nan, nan, 0, 0, 0, 0, 0),
            lambda: mav.command_long_encode(target, 1, mavlink.MAV_CMD_DO_SET_MODE, 0,
                                            nan, nan, nan, 0, 0, 0, 0),
            lambda: mav.command_long_encode(target, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                            float(rng.integers(1000, 60000)), 0, 0, 0, 0, 0, 0),
            lambda: mav.param_set_encode(target, 1, b"MPC_XY_P", nan,
                                         mavlink.MAV_PARAM_TYPE_REAL32),
            lambda: mav.param_request_read_encode(target, 1, b"", 30000),
            lambda: mav.set_position_target_local_ned_encode(
                0, target, 1, mavlink.MAV_FRAME_LOCAL_NED, 0, *[nan] * 11),
            lambda: mav.set_attitude_target_encode(0, target, 1, 0, [nan] * 4, 0, 0, 0, nan),
            lambda: mav.mission_item_int_encode(target, 1, int(rng.integers(65535)), 0, 16, 0,
                                                1, 0, 0, 0, 0, 0, 0, 0),
            lambda: mav.mission_clear_all_encode(target, 1, int(rng.integers(3, 255))),
            lambda: mav.heartbeat_encode(int(rng.integers(256)), int(rng.integers(256)),
                                         int(rng.integers(256)), int(rng.integers(2**32)),
                                         int(rng.integers(256))),
            lambda: mav.file_transfer_protocol_encode(0, target, 1,
                                                      list(rng.bytes(251))),
        )  # fmt: skip
        return choices[int(rng.integers(len(choices)))]()


class Heartbeats:
    """1 Hz heartbeats from the clients' own sockets, as every ground station sends them
    (the autopilot serves telemetry to the stations it heard within the last 5 s)."""

    def __init__(self, clients: list[GcsClient]) -> None:
        mav = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)
        self.beat = mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                         0, 0, 0).pack(mav)  # fmt: skip
        self.clients = clients
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            for client in self.clients:
                client.sock.sendto(self.beat, client.target)
            if self._stop.wait(1.0):
                return

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)


def test_a_cut_off_frame_does_not_swallow_the_next_datagram(free_instance):
    """A datagram ending in half a frame (its header promises 200 bytes more), then one
    holding a whole command: the command comes out of the link, the rest is bad data."""
    ports = Ports(free_instance())
    link = MavlinkLink("gcs", ports.gcs_local_udp, ports.gcs_remote_udp, ports.system_id)
    client = GcsClient(ports.gcs_local_udp, ports.system_id)
    try:
        land = mavlink.MAV_CMD_NAV_LAND
        command = client.mav.command_long_encode(ports.system_id, 1, land, 0, *[0.0] * 7)
        client.send_raw(bytes([0xFD, 200, 0, 0, 0, 1, 1, 76, 0, 0]) + bytes(20))
        client.send(command)
        deadline = time.monotonic() + 2.0
        received: list = []
        while len(received) < 2 and time.monotonic() < deadline:
            received += [message.get_type() for message, _ in link.receive()]
        assert received == ["BAD_DATA", "COMMAND_LONG"]
    finally:
        link.close()
        client.close()


@pytest.mark.closed_loop
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_flood_of_garbage_leaves_the_flight_and_its_commands_alone(
    tmp_path, free_instance, capfd, seed
):
    """Arm, take off to MIS_TAKEOFF_ALT, land: each ACKed within 1 s of its only sending,
    under 250 datagrams/s of garbage on each ground-station port, three seeds."""
    instance = free_instance()
    ports = Ports(instance)
    rig = RigInBackground(tmp_path, instance, duration_s=30.0, speed=1.0)
    wait_until_bound(ports.gcs_local_udp, 60.0)
    gcs = GcsClient(ports.gcs_local_udp, ports.system_id)
    api = GcsClient(ports.api_local_udp, ports.system_id)
    flood = Flood([ports.gcs_local_udp, ports.api_local_udp], ports.system_id, seed)
    acks: dict[str, tuple[int, float]] = {}

    def command(client: GcsClient, name: str, command_id: int, *params: float) -> None:
        start = time.monotonic()
        padded = [*params, *[0.0] * (7 - len(params))]
        client.send(client.mav.command_long_encode(ports.system_id, 1, command_id, 0, *padded))
        ack = client.wait_for("COMMAND_ACK", lambda m: m.command == command_id, ACK_WAIT_S)
        acks[name] = (ack.result, time.monotonic() - start)

    def height_m() -> float:
        return gcs.wait_for("GLOBAL_POSITION_INT").relative_alt / 1000

    heartbeats = Heartbeats([gcs, api])
    try:
        gcs.wait_for("HOME_POSITION", timeout_s=20.0)  # the position estimate is valid
        flood.start()
        time.sleep(1.0)  # garbage before the first command
        command(gcs, "arm", mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        command(gcs, "takeoff", mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan,
                math.nan, math.nan)  # fmt: skip
        command(api, "version", mavlink.MAV_CMD_REQUEST_MESSAGE,
                mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)  # fmt: skip
        deadline = time.monotonic() + 10.0
        while height_m() < 2.3:  # of 2.5: PX4's trajectory closes the last metre slowly
            assert time.monotonic() < deadline, "no take-off to 2.3 m within 10 s"
        command(gcs, "land", mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan, math.nan, math.nan,
                math.nan)  # fmt: skip
        gcs.wait_for("HEARTBEAT", lambda m: not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED,
                     timeout_s=15.0)  # fmt: skip
        status = gcs.wait_for("SYS_STATUS")
    finally:
        sent = flood.stop()
        heartbeats.stop()
        gcs.close()
        api.close()
    result = rig.finish(timeout_s=60)
    assert {name: result for name, (result, _) in acks.items()} == dict.fromkeys(
        ("arm", "takeoff", "version", "land"), mavlink.MAV_RESULT_ACCEPTED
    )
    assert sent > 2000
    assert status.errors_comm > sent // 4  # the garbage, counted (the cut and bad-CRC kinds)
    altitude_m = -pyulog.ULog(str(result.rig_log)).get_dataset(
        "vehicle_local_position_groundtruth").data["z"]  # fmt: skip
    assert 2.2 < altitude_m.max() < 2.9
    assert altitude_m[-1] < 0.1
    console = capfd.readouterr().err.splitlines()
    assert sum(GARBAGE_LINE in line for line in console) == 1, console
