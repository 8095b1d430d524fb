"""A lockstep simulator that can misbehave, for what the real rig cannot do: bytes that are
not MAVLink on PX4's simulator link while the autopilot flies.

It serves quad_model's F450 and its sensor physics (SI samples, no chips) behind PX4's
simulator API on TCP, and runs the real process (``python -m rig.autopilots.reference``).
Everything a well-behaved simulator does is tested through the rig itself
(``test_end_to_end.py``).
"""

from __future__ import annotations

import select
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from quad_model import QuadModel, SensorSuite, load_vehicle
from rig.mavlink.px4_api import ActuatorMode, Ports, mavlink
from rig.mavlink.sim_messages import hil_gps, hil_sensor_frame

WAIT_S = 10.0


class MiniRig:
    """Runs ``python -m rig.autopilots.reference --instance I`` against the F450 model."""

    def __init__(self, instance: int, seed: int, log_path: Path, imu_rate_hz: int = 250,
                 stderr_path: Path | None = None) -> None:  # fmt: skip
        vehicle = load_vehicle("f450_high_precision")
        model_rng, sensor_rng = np.random.default_rng(seed).spawn(2)
        self.model = QuadModel(vehicle, model_rng)
        self.sensors = SensorSuite(vehicle, self.model.environment, sensor_rng, imu_rate_hz)
        self.frame_us = 1_000_000 // imu_rate_hz
        self.throttle = np.zeros(4)
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=200)
        self.parser = mavlink.MAVLink(None)
        self.listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.listener.bind(("127.0.0.1", Ports(instance).simulator_tcp))
        self.listener.listen(1)
        self.listener.settimeout(30.0)
        self._stderr = None if stderr_path is None else stderr_path.open("w")
        self.process = subprocess.Popen(
            [sys.executable, "-m", "rig.autopilots.reference", "--instance", str(instance), "--log",
             str(log_path)], stderr=self._stderr,
        )  # fmt: skip
        try:
            self.sim, _ = self.listener.accept()
        except OSError:  # the autopilot never connected: leave no process or port behind
            self.process.kill()
            self.process.wait()
            self.listener.close()
            if self._stderr is not None:
                self._stderr.close()
            raise
        self.sim.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.armed = False

    @property
    def altitude_m(self) -> float:
        return -float(self.model.truth.position_ned_m[2])

    def step(self, seconds: float, collect=lambda: None) -> None:
        """Advance in lockstep; ``collect`` runs after each frame (ground stations listen)."""
        for _ in range(round(seconds * 1e6 / self.frame_us)):
            self.model.advance(self.throttle, self.frame_us * 1e-6)
            truth = self.model.truth
            time_us = truth.time_us
            readings = self.sensors.sample(truth)
            imu, mag, baro, gps = readings.imu, readings.mag, readings.baro, readings.gps
            data = b""
            if gps is not None:
                fix = hil_gps(self.mav, time_us, lat_deg=gps.lat_deg, lon_deg=gps.lon_deg,
                              alt_amsl_m=gps.alt_amsl_m, vel_ned_mps=gps.vel_ned_mps,
                              eph_m=gps.eph_m, epv_m=gps.epv_m, fix_type=gps.fix_type,
                              satellites_visible=gps.satellites_visible)  # fmt: skip
                data += fix.pack(self.mav)
            data += hil_sensor_frame(
                self.mav, time_us, accel_mps2=imu.accel_mps2, gyro_radps=imu.gyro_radps,
                mag_gauss=None if mag is None else mag.field_gauss,
                baro=None if baro is None else (baro.pressure_pa, baro.temperature_degc),
            )  # fmt: skip
            self.sim.sendall(data)
            self.throttle = np.array(self._await_controls(time_us))
            collect()

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
            if self._stderr is not None:
                self._stderr.close()
