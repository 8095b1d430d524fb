"""A lockstep simulator for the autopilot-process tests: the test plant behind PX4's
simulator API on TCP, plus a pymavlink ground station on UDP.

It is the smallest rig that exercises the real process (``python -m rig.autopilot``) over real
loopback sockets; the rig's own closed loop (``rig run``) is tested in ``tests/rig``.
"""

from __future__ import annotations

import select
import socket
import subprocess
import sys
import time
from pathlib import Path

from rig.px4_sim_api import ActuatorMode, Ports, mavlink
from rig.sim_messages import hil_gps, hil_sensor
from tests.rig.autopilot.plant import QuadPlant

WAIT_S = 10.0


class MiniRig:
    """Runs ``python -m rig.autopilot --instance I`` against a :class:`QuadPlant`."""

    def __init__(self, instance: int, plant: QuadPlant, log_path: Path, imu_rate_hz: int = 250,
                 mag: bool = True) -> None:  # fmt: skip
        self.ports = Ports(instance)
        self.plant = plant
        self.imu_rate_hz = imu_rate_hz
        self.mag = mag
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=200)
        self.parser = mavlink.MAVLink(None)
        self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.listener.bind(("127.0.0.1", self.ports.simulator_tcp))
        self.listener.listen(1)
        self.listener.settimeout(30.0)
        self.process = subprocess.Popen(
            [sys.executable, "-m", "rig.autopilot", "--instance", str(instance), "--log",
             str(log_path)],
        )  # fmt: skip
        self.sim, _ = self.listener.accept()
        self.sim.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.frame = 0
        self.armed = False

    def step(self, seconds: float, gcs: list[GroundStation] = ()) -> None:
        """Advance in lockstep; ground stations collect what arrives meanwhile."""
        dt_s = 1.0 / self.imu_rate_hz
        for _ in range(round(seconds * self.imu_rate_hz)):
            plant = self.plant
            frame = plant.sensors(self.frame, self.imu_rate_hz)
            time_us = plant.time_us + 1
            data = b""
            if frame.gps is not None:
                g = frame.gps
                data += hil_gps(self.mav, time_us, lat_deg=g.lat_deg, lon_deg=g.lon_deg,
                                alt_amsl_m=g.alt_amsl_m, vel_ned_mps=g.velocity_ned_mps,
                                eph_m=g.eph_m, epv_m=g.epv_m, fix_type=g.fix_type,
                                satellites_visible=g.satellites_used).pack(self.mav)  # fmt: skip
            mag = frame.mag_gauss if self.mag else None
            baro = None
            if frame.baro_pressure_pa is not None:
                baro = (frame.baro_pressure_pa, frame.baro_temperature_degc)
            data += hil_sensor(self.mav, time_us, accel_mps2=frame.accel_mps2,
                               gyro_radps=frame.gyro_radps, mag_gauss=mag,
                               baro=baro).pack(self.mav)  # fmt: skip
            self.sim.sendall(data)
            motors = self._await_controls(time_us)
            plant.step(motors, dt_s)
            self.frame += 1
            for station in gcs:
                station.collect()

    def send_raw(self, data: bytes) -> None:
        """Bytes on the simulator link between frames (fuzzing)."""
        self.sim.sendall(data)

    def _await_controls(self, time_us: int) -> tuple[float, ...]:
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            readable, _, _ = select.select([self.sim], [], [], 0.5)
            if not readable:
                continue
            data = self.sim.recv(65536)
            assert data, f"the autopilot closed the link (exit {self.process.poll()})"
            for message in self.parser.parse_buffer(data) or []:
                if message.get_type() == "HIL_ACTUATOR_CONTROLS":
                    assert message.time_usec == time_us
                    self.armed = bool(message.mode & ActuatorMode.SAFETY_ARMED)
                    return tuple(message.controls[:4]) if self.armed else (0.0,) * 4
        raise AssertionError(f"no HIL_ACTUATOR_CONTROLS for time_usec={time_us}")

    def close(self) -> int:
        """Close the link: the autopilot ends (PX4 would spin; ours exits and says why)."""
        self.sim.close()
        self.listener.close()
        try:
            return self.process.wait(timeout=WAIT_S)
        finally:
            if self.process.poll() is None:
                self.process.kill()


class GroundStation:
    """A pymavlink client on one of the autopilot's UDP links; keeps everything it hears."""

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

    def send(self, *messages) -> None:
        for message in messages:
            self.sock.sendto(message.pack(self.mav), self.target)

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.target)

    def collect(self) -> None:
        while True:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                return
            messages = self.parser.parse_buffer(data) or []
            self.received.extend(messages)
            self.statustexts += [m.text for m in messages if m.get_type() == "STATUSTEXT"]

    def wait_for(self, kind: str, condition=lambda m: True, timeout_s: float = WAIT_S):
        """The first not-yet-consumed message of ``kind`` that meets ``condition``."""
        deadline = time.monotonic() + timeout_s
        while True:
            self.collect()
            for i, message in enumerate(self.received):
                if message.get_type() == kind and condition(message):
                    del self.received[: i + 1]
                    return message
            assert time.monotonic() < deadline, f"no {kind} within {timeout_s} s"
            time.sleep(0.005)

    def command(self, command: int, *params: float):
        padded = [*params, *[0.0] * (7 - len(params))]
        self.send(self.mav.command_long_encode(self.target_system, 1, command, 0, *padded))
        return self.wait_for("COMMAND_ACK", lambda m: m.command == command)

    def close(self) -> None:
        self.sock.close()
