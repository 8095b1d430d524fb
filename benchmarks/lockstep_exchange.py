"""The lockstep exchange alone: the floor under any closed loop over PX4's simulator API.

A frame of the rig's closed loop ends with one exchange between two processes: the
simulator sends HIL_SENSOR and blocks until the autopilot answers HIL_ACTUATOR_CONTROLS,
over TCP on loopback (PX4's simulator API). Here the two sides do nothing else: no
model, no sensors, no control. What one exchange costs is the most frames per second a
Python simulator and a Python autopilot can reach on this machine, whatever they compute;
``bench_rig`` prints it beside the rig's own figures.

Measured twice: each message encoded and decoded as the rig (``rig.mavlink.sim_messages``)
and the reference autopilot (pymavlink's parser) do, and with the same bytes packed once
beforehand (the socket round trip and the two process wake-ups alone).

``python -m benchmarks.lockstep_exchange PORT FRAMES MODE`` is the autopilot's side (the
benchmark starts it).
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from pathlib import Path

from rig.mavlink.px4_api import LOCKSTEP_FLAG, mavlink
from rig.mavlink.sim_messages import actuator_controls_from_frame, hil_sensor_frame

REPO = Path(__file__).resolve().parent.parent
MODES = ("pymavlink", "bytes")
#: Seconds either side waits for the other (start-up or one exchange) before it gives up.
TIMEOUT_S = 30.0
#: A quad's answer: four motor commands of PX4's 16 outputs.
_MOTORS = 4


def _sensor(mav: mavlink.MAVLink, frame: int) -> bytes:
    """One HIL_SENSOR as the rig sends it at an IMU-only frame (accel and gyro)."""
    time_us = (frame + 1) * 1000
    return hil_sensor_frame(
        mav, time_us, accel_mps2=(0.1, -0.2, -9.8), gyro_radps=(0.01, 0.02, -0.03)
    )


def _controls(mav: mavlink.MAVLink, time_us: int) -> bytes:
    """One HIL_ACTUATOR_CONTROLS as an autopilot answers in lockstep."""
    return mavlink.MAVLink_hil_actuator_controls_message(
        time_us, [0.5] * _MOTORS + [0.0] * (16 - _MOTORS), 129, LOCKSTEP_FLAG
    ).pack(mav)


def _receive(link: socket.socket) -> bytes:
    data = link.recv(4096)
    if not data:
        raise ConnectionError("the other side of the exchange closed the link")
    return data


def _answer(port: int, frames: int, mode: str) -> None:
    """The autopilot's side: answer every HIL_SENSOR, nothing else."""
    with socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S) as link:
        link.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        mav = mavlink.MAVLink(None, 1, 1)
        packed = _controls(mav, 0)
        for _ in range(frames):
            if mode == "bytes":
                _receive(link)
                link.sendall(packed)
                continue
            sensors: list = []
            while not sensors:
                sensors = mav.parse_buffer(_receive(link)) or []
            link.sendall(_controls(mav, sensors[-1].time_usec))


def exchange_us(frames: int, mode: str) -> float:
    """Mean wall time (µs) of one exchange over ``frames`` frames, ``mode`` in :data:`MODES`."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, not {mode!r}")
    with socket.create_server(("127.0.0.1", 0)) as server:
        server.settimeout(TIMEOUT_S)
        port = server.getsockname()[1]
        peer = subprocess.Popen(
            [sys.executable, "-m", "benchmarks.lockstep_exchange", str(port), str(frames), mode],
            cwd=REPO,
        )
        try:
            link, _ = server.accept()
            with link:
                link.settimeout(TIMEOUT_S)
                link.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                mav = mavlink.MAVLink(None, 1, 1)
                packed = _sensor(mav, 0)
                started = time.perf_counter()
                for frame in range(frames):
                    if mode == "bytes":
                        link.sendall(packed)
                        _receive(link)
                        continue
                    link.sendall(_sensor(mav, frame))
                    answered = False
                    while not answered:  # the rig's decoder, pymavlink's for anything else
                        data = _receive(link)
                        answered = bool(
                            actuator_controls_from_frame(data, _MOTORS) or mav.parse_buffer(data)
                        )
                elapsed = time.perf_counter() - started
        except BaseException:  # a timeout or Ctrl-C: the peer must not outlive the benchmark
            peer.kill()
            raise
        finally:
            peer.wait(timeout=TIMEOUT_S)
    if peer.returncode != 0:
        raise RuntimeError(f"the answering process exited with status {peer.returncode}")
    return elapsed / frames * 1e6


if __name__ == "__main__":
    _answer(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3])
