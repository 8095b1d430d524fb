"""A small quadcopter plant and sensor set for the autopilot's in-process closed-loop tests.

The project's full model (``quad_model``) is the rig's; these tests need a plant whose every
number is visible in one page so a failure can be reasoned about: a rigid body with PX4
SITL airframe 10016's rotor layout, motors linear in throttle with a first-order lag, linear
drag, a flat ground, and sensors with seeded white noise and a constant gyro bias.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from quad_model.frames import (
    STANDARD_GRAVITY_MPS2,
    ned_to_geodetic,
    quat_multiply,
    quat_to_dcm,
)
from rig.autopilot.sensors import GpsFix, GroundTruth, SensorFrame

HOME = (47.397742, 8.545594, 488.0)
#: WMM2025 at HOME (quad_model.environment.DEFAULT_MAGNETIC_FIELD), NED gauss.
MAG_NED_GAUSS = np.array([0.2150, 0.0133, 0.4329])
ROTORS_XY_M = np.array([[0.15, 0.245], [-0.15, -0.19], [0.15, -0.245], [-0.15, 0.19]])
ROTOR_SPIN = np.array([1.0, 1.0, -1.0, -1.0])  # +1 CCW seen from above: positive yaw reaction


@dataclass
class QuadPlant:
    """State in NED/FRD; ``hover_throttle`` sets the thrust so that it hovers there."""

    rng: np.random.Generator
    mass_kg: float = 1.5
    inertia_kgm2: np.ndarray = field(default_factory=lambda: np.diag([0.029, 0.029, 0.055]))
    hover_throttle: float = 0.55
    motor_time_constant_s: float = 0.03
    moment_ratio_m: float = 0.05
    drag_nspm: float = 0.3
    gyro_bias_radps: np.ndarray = field(default_factory=lambda: np.array([0.01, -0.008, 0.005]))
    gyro_noise_radps: float = 0.003
    accel_noise_mps2: float = 0.05
    mag_noise_gauss: float = 0.002
    baro_noise_pa: float = 1.0
    gps_noise_m: float = 0.3
    gps_enabled: bool = True

    def __post_init__(self) -> None:
        self.position = np.zeros(3)
        self.velocity = np.zeros(3)
        self.q = np.array([1.0, 0.0, 0.0, 0.0])
        self.rates = np.zeros(3)
        self.throttle = np.zeros(4)
        self.time_us = 0
        self.thrust_max_n = self.mass_kg * STANDARD_GRAVITY_MPS2 / (4 * self.hover_throttle)
        self._specific_force = np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2])

    def step(self, motors: tuple[float, ...], dt_s: float) -> None:
        alpha = dt_s / self.motor_time_constant_s
        self.throttle += (np.clip(motors, 0.0, 1.0) - self.throttle) * min(alpha, 1.0)
        thrust = self.thrust_max_n * self.throttle
        torque = np.array(
            [
                float(-(ROTORS_XY_M[:, 1] * thrust).sum()),  # y_i × (-T_i ẑ) → roll
                float((ROTORS_XY_M[:, 0] * thrust).sum()),
                float((ROTOR_SPIN * self.moment_ratio_m * thrust).sum()),
            ]
        )
        r = quat_to_dcm(self.q)
        force_body = np.array([0.0, 0.0, -thrust.sum()])
        gravity = np.array([0.0, 0.0, STANDARD_GRAVITY_MPS2])
        accel = (r @ force_body - self.drag_nspm * self.velocity) / self.mass_kg + gravity
        velocity_before = self.velocity
        inertia = self.inertia_kgm2
        rate_dot = np.linalg.solve(inertia, torque - np.cross(self.rates, inertia @ self.rates))
        self.velocity = self.velocity + accel * dt_s
        self.position = self.position + self.velocity * dt_s
        self.rates = self.rates + rate_dot * dt_s
        if self.position[2] >= 0.0 and self.velocity[2] >= 0.0:  # resting on flat ground
            self.position[2] = 0.0
            self.velocity[:] = 0.0
            self.rates[:] = 0.0
        # what an accelerometer feels, the touchdown's impulse included
        self._specific_force = r.T @ ((self.velocity - velocity_before) / dt_s - gravity)
        half = self.rates * (0.5 * dt_s)
        q = quat_multiply(self.q, np.array([1.0, *half]))
        self.q = q / np.linalg.norm(q)
        self.time_us += round(dt_s * 1e6)

    def sensors(self, frame: int, imu_rate_hz: int = 1000) -> SensorFrame:
        """The sensor frame at the current time: IMU always, mag 100 Hz, baro 50 Hz, GPS 10 Hz."""
        n = self.rng.standard_normal
        r = quat_to_dcm(self.q)
        mag = baro = gps = None
        if frame % (imu_rate_hz // 100) == 0:
            mag = r.T @ MAG_NED_GAUSS + n(3) * self.mag_noise_gauss
        if frame % (imu_rate_hz // 50) == 0:
            altitude = HOME[2] - self.position[2]
            baro = 101325.0 * (1 - 0.0065 * altitude / 288.15) ** 5.25588 + n() * self.baro_noise_pa
        if self.gps_enabled and frame % (imu_rate_hz // 10) == 0:
            lat, lon, alt = ned_to_geodetic(self.position + n(3) * self.gps_noise_m, *HOME)
            v = self.velocity + n(3) * 0.05
            gps = GpsFix(lat, lon, alt, (v[0], v[1], v[2]), 0.8, 1.2, 3, 12)
        return SensorFrame(
            accel_mps2=self._specific_force + n(3) * self.accel_noise_mps2,
            gyro_radps=self.rates + self.gyro_bias_radps + n(3) * self.gyro_noise_radps,
            mag_gauss=mag,
            baro_pressure_pa=baro,
            baro_temperature_degc=None if baro is None else 15.0,
            gps=gps,
        )

    def truth(self) -> GroundTruth:
        lat, lon, alt = ned_to_geodetic(self.position, *HOME)
        return GroundTruth(self.q.copy(), lat, lon, alt, self.velocity.copy())


def fly(controller, plant: QuadPlant, seconds: float, imu_rate_hz: int = 1000, on_frame=None):
    """Run the closed loop for ``seconds`` (lockstep: one IMU frame, one answer, one step)."""
    dt_s = 1.0 / imu_rate_hz
    for _ in range(round(seconds * imu_rate_hz)):
        frame = plant.time_us // round(dt_s * 1e6)
        controller.observe_truth(plant.truth())
        controls = controller.update(plant.sensors(frame, imu_rate_hz), plant.time_us + 1)
        plant.step(controls.motors, dt_s)
        if on_frame is not None:
            on_frame(controller, plant)


def heading_rad(q) -> float:
    w, x, y, z = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
