"""A pymavlink ground station on one of the autopilot's UDP links, for the process tests.

It binds an ephemeral port and talks to the link's bound port (18570+i for the GCS link,
14580+i for the API link); the autopilot answers whoever last sent it a valid message, as
PX4 SITL does. Waits are bounded in wall time and fail with what was awaited.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable

from rig.mavlink.px4_api import mavlink

WAIT_S = 10.0


class GcsClient:
    """Sends commands, keeps everything it hears, and waits for answers."""

    def __init__(self, port: int, target_system: int) -> None:
        self.target_system = target_system
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.target = ("127.0.0.1", port)
        self.mav = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)
        self.parser = mavlink.MAVLink(None)
        self.received: list = []
        self.statustexts: list[str] = []  # every one ever heard, never consumed
        self.reached: list[int] = []  # every MISSION_ITEM_REACHED seq, in order

    def send(self, *messages) -> None:
        for message in messages:
            self.sock.sendto(message.pack(self.mav), self.target)

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.target)

    def heartbeat(self) -> None:
        """Announce this client, so the autopilot streams telemetry to it."""
        self.send(self.mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                            0, 0, 0))  # fmt: skip

    def collect(self) -> None:
        while True:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                return
            messages = self.parser.parse_buffer(data) or []
            self.received.extend(messages)
            for message in messages:
                if message.get_type() == "STATUSTEXT":
                    self.statustexts.append(message.text)
                elif message.get_type() == "MISSION_ITEM_REACHED":
                    self.reached.append(message.seq)

    def wait_for(self, kind: str, condition: Callable = lambda m: True,
                 timeout_s: float = WAIT_S):  # fmt: skip
        """The first not-yet-consumed message of ``kind`` that meets ``condition``."""
        deadline = time.monotonic() + timeout_s
        while True:
            self.collect()
            for i, message in enumerate(self.received):
                if message.get_type() == kind and condition(message):
                    del self.received[: i + 1]
                    return message
            assert time.monotonic() < deadline, f"no {kind} within {timeout_s} s"
            time.sleep(0.002)

    def command(self, command: int, *params: float):
        padded = [*params, *[0.0] * (7 - len(params))]
        self.send(self.mav.command_long_encode(self.target_system, 1, command, 0, *padded))
        return self.wait_for("COMMAND_ACK", lambda m: m.command == command)

    def upload_mission(self, items: list) -> int:
        """The mission protocol from the ground station's side; returns MISSION_ACK.type."""
        self.send(self.mav.mission_count_encode(self.target_system, 1, len(items),
                                                mavlink.MAV_MISSION_TYPE_MISSION))  # fmt: skip
        for _ in items:
            request = self.wait_for("MISSION_REQUEST_INT")
            self.send(items[request.seq])
        return self.wait_for("MISSION_ACK").type

    def close(self) -> None:
        self.sock.close()
