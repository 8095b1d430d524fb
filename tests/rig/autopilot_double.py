"""TEST DOUBLE: a minimal autopilot process speaking PX4's side of the simulator link.

Not a flight controller: it exists so the rig's tests can drive the link with a peer that
behaves exactly as the contract describes, or that misbehaves on purpose.

``python tests/rig/autopilot_double.py --port P --behaviour B [--after N]``

Behaviours:
- ``px4``: like PX4 SITL: connect with retries, send HEARTBEAT (MAV_AUTOPILOT_PX4) and
  SET_MESSAGE_INTERVAL for HIL_STATE_QUATERNION (5000 µs), stay silent for the first
  ``--after`` frames (PX4 boots for 52–112 ms of simulated time), then answer every
  HIL_SENSOR with ``id = 0`` with one disarmed HIL_ACTUATOR_CONTROLS echoing ``time_usec``.
  With ``--throttle X`` it answers armed, every motor of ``--motors`` (4) at X, from frame
  ``--arm-after`` on (a real autopilot is disarmed while the rig freewheels, so the answered frames
  before lockstep do not change the flight).
- ``hang``: answers ``--after`` frames, then stops answering but keeps the link open.
- ``close``: answers ``--after`` frames, then closes the link.
- ``garbage``: answers ``--after`` frames, then sends random bytes instead of answers.
- ``nan``: answers ``--after`` frames, then sends NaN motor commands while armed.
- ``twice``: answers ``--after`` frames, then sends every answer twice (PX4 may publish
  its outputs twice in one lockstep step).

``--answer-delay-ms D`` holds each answer D ms: an autopilot that computes longer than the
rig's own work between sending a frame and asking for its answer. ``--state-interval-us I``
asks for HIL_STATE_QUATERNION every I µs instead (MAVLink: -1 stops it, 0 a default rate).

Each received frame is appended to ``--record`` (one JSON line: msg type and fields), so a
test can check what reached the autopilot.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import socket
import sys
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink  # after MAVLINK20 is set

ARMED_MODE = 1 | 128


def connect(port: int, timeout_s: float = 30.0) -> socket.socket:
    """Retry ``connect()`` as PX4's simulator_mavlink does, until the rig accepts."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            sock = socket.create_connection(("127.0.0.1", port), timeout=1.0)
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.01)
            continue
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(None)
        return sock


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--behaviour", default="px4")
    parser.add_argument("--after", type=int, default=0)
    parser.add_argument("--throttle", type=float, default=None)
    parser.add_argument("--motors", type=int, default=4)
    parser.add_argument("--arm-after", type=int, default=0)
    parser.add_argument("--record", default=None)
    parser.add_argument("--ignore-sigint", action="store_true", help="a hung shutdown")
    parser.add_argument("--answer-delay-ms", type=float, default=0.0)
    parser.add_argument("--state-interval-us", type=int, default=5000)
    args = parser.parse_args()
    if args.ignore_sigint:
        signal.signal(signal.SIGINT, signal.SIG_IGN)

    sock = connect(args.port)
    mav = mavlink.MAVLink(None, 1, 1)
    record = open(args.record, "w") if args.record else None  # noqa: SIM115 - whole run
    sock.sendall(
        mav.heartbeat_encode(
            mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 0
        ).pack(mav)
        + mav.command_long_encode(
            0, 0, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
            mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, args.state_interval_us, 0, 0, 0, 0, 0,
        ).pack(mav)
    )  # fmt: skip
    try:
        answer_frames(sock, mav, record, args)
    except KeyboardInterrupt:
        # The rig sends SIGINT before it closes the link, so the last frame may still be
        # unread in the socket: record it too, as a test compares every frame sent.
        sock.setblocking(False)
        try:
            while data := sock.recv(65536):
                parse_and_record(mav, data, record)
        except OSError:
            pass


def parse_and_record(mav: mavlink.MAVLink, data: bytes, record) -> list:
    messages = mav.parse_buffer(data) or []
    if record is not None:
        for message in messages:
            record.write(json.dumps(message.to_dict()) + "\n")
        record.flush()
    return messages


def answer_frames(sock: socket.socket, mav: mavlink.MAVLink, record, args) -> None:
    frames = 0
    rng_bytes = bytes(range(7, 256, 13)) * 4  # deterministic "garbage"
    while True:
        data = sock.recv(65536)
        if not data:
            return
        for message in parse_and_record(mav, data, record):
            if message.get_type() != "HIL_SENSOR" or message.id != 0:
                continue
            frames += 1
            misbehaving = frames > args.after
            if args.behaviour == "px4" and not misbehaving:
                continue  # still booting: PX4 does not answer yet
            if misbehaving and args.behaviour == "hang":
                continue
            if misbehaving and args.behaviour == "close":
                sock.close()
                return
            if misbehaving and args.behaviour == "garbage":
                sock.sendall(rng_bytes)
                continue
            if misbehaving and args.behaviour == "nan":
                controls = [math.nan] * 4 + [0.0] * 12
                mode = ARMED_MODE
            elif args.throttle is not None and frames > args.arm_after:
                controls = [args.throttle] * args.motors + [0.0] * (16 - args.motors)
                mode = ARMED_MODE
            else:
                controls, mode = [0.0] * 16, 1
            answer = mav.hil_actuator_controls_encode(message.time_usec, controls, mode, 1)
            if args.answer_delay_ms:
                time.sleep(args.answer_delay_ms / 1e3)
            copies = 2 if misbehaving and args.behaviour == "twice" else 1
            sock.sendall(answer.pack(mav) * copies)


if __name__ == "__main__":
    try:
        main()
    except (BrokenPipeError, ConnectionResetError, KeyboardInterrupt):
        sys.exit(0)  # the rig ended the run (it sends SIGINT first, like Ctrl-C)
