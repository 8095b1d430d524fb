"""The anchor of the PX4 figures: PX4 SITL and the barest simulator that flies it.

Issue 16 sets the goal for PX4 + rig as a share of PX4 + "a bare Python simulator" on the
same machine; this is that simulator, so the anchor is measured in the same run as the rig
(a shared machine's load then shifts both). It keeps only what PX4 needs to arm and fly:
the same compiled model and sensor physics as the rig, HIL_SENSOR and HIL_GPS in lockstep
on the simulator link, HIL_ACTUATOR_CONTROLS applied straight as throttle, and a ground
link that arms and takes off. No chips, no logs, no faults, no scenario, no progress.
"""

from __future__ import annotations

import gc
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quad_model import QuadModel, SensorReadings, SensorSuite, load_vehicle
from quad_model.environment import Environment
from rig.autopilots.px4 import Px4Build, Px4Sitl, px4_parameters
from rig.mavlink.ground_link import GroundLink
from rig.mavlink.px4_api import Ports, mavlink
from rig.mavlink.sim_messages import hil_gps, hil_sensor_frame
from rig.mavlink.simulator_link import LinkTimeouts, SimulatorLink


@dataclass(frozen=True)
class BareRun:
    """What the anchor measured: lockstep frames flown after the take-off command."""

    simulated_s: float
    wall_s: float
    altitude_m: float  # height reached (shows that PX4 really flew)

    @property
    def real_time_factor(self) -> float:
        return self.simulated_s / self.wall_s


def fly_bare(build: Px4Build, *, instance: int, imu_hz: int, arm_s: float, simulated_s: float,
             vehicle_name: str = "f450_high_precision", seed: int = 1) -> BareRun:  # fmt: skip
    """Start PX4, arm at ``arm_s``, take off to 2 m, and fly ``simulated_s`` more."""
    vehicle = load_vehicle(vehicle_name)
    environment = Environment()
    model_rng, sensor_rng = np.random.default_rng(seed).spawn(2)
    model = QuadModel(vehicle, model_rng, environment)
    sensors = SensorSuite(vehicle, environment, sensor_rng, imu_hz, 100, 50)
    frame_us = 1_000_000 // imu_hz
    ports = Ports(instance)
    with tempfile.TemporaryDirectory() as folder:
        params, _ = px4_parameters(vehicle, model.hover_throttle(), imu_hz, (), build)
        px4 = Px4Sitl(build, Path(folder), instance, params)
        motors = vehicle.propulsion.rotor_count
        link = SimulatorLink(ports, LinkTimeouts(connect_s=60, answer_s=30), motors=motors,
                             peer_exit=px4.exit_description)  # fmt: skip
        ground = GroundLink(ports, environment.home)
        try:
            px4.start()
            link.accept("PX4 SITL (the bare simulator's anchor)")
            throttle = np.zeros(motors)
            arm_frame = round(arm_s * 1e6) // frame_us
            last_frame = arm_frame + round(simulated_s * 1e6) // frame_us
            poll_every = max(1, imu_hz // 100)
            actions = [("arm", ground.arm_when_ready()), ("takeoff", ground.takeoff(2.0))]
            wall_start = 0.0
            held = False  # PX4 on one CPU once its start-up script has ended, as the rig does
            for frame in range(1, last_frame + 1):
                time_us = frame * frame_us
                model.advance(throttle, frame_us / 1e6)
                link.send_frame(
                    time_us, _sensor_messages(link, time_us, sensors.sample(model.truth))
                )
                if frame == arm_frame:
                    gc.collect()  # as the rig does before its clock: no full pass in the frames
                    wall_start = time.perf_counter()
                if frame >= arm_frame and actions and not ground.busy:
                    ground.start(*actions.pop(0), time_us / 1e6)
                if ground.busy or frame % poll_every == 0:
                    ground.poll(time_us / 1e6)  # PX4's acks; a refused command raises
                    held = held or px4.settle()
                controls = link.answer(time_us)
                if controls is not None:
                    throttle = np.asarray(controls.motors)
            wall_s = time.perf_counter() - wall_start
        finally:
            ground.close()
            link.close()
            px4.stop()
    altitude_m = -float(model.truth.position_ned_m[2])
    return BareRun(simulated_s, wall_s, altitude_m)


def _sensor_messages(
    link: SimulatorLink, time_us: int, readings: SensorReadings
) -> list[mavlink.MAVLink_message | bytes]:
    """HIL_SENSOR (mag and baro when sampled) and HIL_GPS at its epochs, from SI samples."""
    imu, mag, baro, gps = readings.imu, readings.mag, readings.baro, readings.gps
    messages: list[mavlink.MAVLink_message | bytes] = [hil_sensor_frame(
        link.mav, time_us, accel_mps2=imu.accel_mps2, gyro_radps=imu.gyro_radps,
        mag_gauss=None if mag is None else mag.field_gauss,
        baro=None if baro is None else (baro.pressure_pa, baro.temperature_degc),
    )]  # fmt: skip
    if gps is not None:
        messages.append(hil_gps(
            link.mav, time_us, lat_deg=gps.lat_deg, lon_deg=gps.lon_deg,
            alt_amsl_m=gps.alt_amsl_m, vel_ned_mps=gps.vel_ned_mps, eph_m=gps.eph_m,
            epv_m=gps.epv_m, fix_type=gps.fix_type, satellites_visible=gps.satellites_visible,
        ))  # fmt: skip
    return messages
