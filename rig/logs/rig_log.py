"""``rig.ulg``: what the rig knows, under PX4's topic and field names.

Ground truth uses PX4 SITL's ``*_groundtruth`` topics (same formats as
``vehicle_attitude``, ``vehicle_local_position``, ``vehicle_angular_velocity``), the
sensor data is logged as delivered to the autopilot (after the chips and faults:
``sensor_combined``, ``sensor_mag``, ``sensor_baro``, ``sensor_gps``, the rangefinder's
``distance_sensor``, the flow chip's ``sensor_optical_flow``), the autopilot's
commands as ``actuator_motors`` (0..1) and the PWM the capture core measured as
``actuator_outputs`` (µs). Field names and types follow PX4's ``msg/*.msg`` (checked
against a real PX4 v1.17 log's format section); only the fields the rig can fill are
declared, which ULog readers accept. Rig events (faults, lockstep waits, commands) are
logged messages; the scenario, seed and vehicle are info entries and parameters.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from fpga_hdl.chips.ublox.driver import GpsFix
from quad_model.frames import yaw_from_quat
from quad_model.model import VehicleTruth
from quad_model.vehicle import MAX_ROTORS
from rig.logs.ulog_writer import ULogWriter

_ATTITUDE = [("uint64_t", "timestamp_sample"), ("float[4]", "q"), ("float[4]", "delta_q_reset"),
             ("uint8_t", "quat_reset_counter")]  # fmt: skip
_LOCAL_POSITION = [
    ("uint64_t", "timestamp_sample"), ("double", "ref_lat"), ("double", "ref_lon"),
    ("float", "x"), ("float", "y"), ("float", "z"), ("float", "vx"), ("float", "vy"),
    ("float", "vz"), ("float", "ax"), ("float", "ay"), ("float", "az"), ("float", "heading"),
    ("float", "ref_alt"), ("bool", "xy_valid"), ("bool", "z_valid"), ("bool", "v_xy_valid"),
    ("bool", "v_z_valid"),
]  # fmt: skip
_ANGULAR_VELOCITY = [("uint64_t", "timestamp_sample"), ("float[3]", "xyz"),
                     ("float[3]", "xyz_derivative")]  # fmt: skip

TOPICS: dict[str, list[tuple[str, str]]] = {
    "vehicle_attitude_groundtruth": _ATTITUDE,
    "vehicle_local_position_groundtruth": _LOCAL_POSITION,
    "vehicle_angular_velocity_groundtruth": _ANGULAR_VELOCITY,
    "sensor_combined": [
        ("float[3]", "gyro_rad"), ("uint32_t", "gyro_integral_dt"),
        ("int32_t", "accelerometer_timestamp_relative"), ("float[3]", "accelerometer_m_s2"),
        ("uint32_t", "accelerometer_integral_dt"), ("uint8_t", "accelerometer_clipping"),
        ("uint8_t", "gyro_clipping"),
    ],
    "sensor_mag": [("uint64_t", "timestamp_sample"), ("uint32_t", "device_id"), ("float", "x"),
                   ("float", "y"), ("float", "z"), ("float", "temperature"),
                   ("uint32_t", "error_count")],
    "sensor_baro": [("uint64_t", "timestamp_sample"), ("uint32_t", "device_id"),
                    ("float", "pressure"), ("float", "temperature"), ("uint32_t", "error_count")],
    "sensor_gps": [
        ("uint64_t", "timestamp_sample"), ("double", "latitude_deg"), ("double", "longitude_deg"),
        ("double", "altitude_msl_m"), ("float", "eph"), ("float", "epv"), ("float", "vel_m_s"),
        ("float", "vel_n_m_s"), ("float", "vel_e_m_s"), ("float", "vel_d_m_s"),
        ("float", "cog_rad"), ("uint8_t", "fix_type"), ("bool", "vel_ned_valid"),
        ("uint8_t", "satellites_used"),
    ],
    "distance_sensor": [("uint32_t", "device_id"), ("float", "min_distance"),
                        ("float", "max_distance"), ("float", "current_distance"),
                        ("float", "variance"), ("int8_t", "signal_quality"), ("uint8_t", "type"),
                        ("uint8_t", "orientation")],
    "sensor_optical_flow": [("uint64_t", "timestamp_sample"), ("float[2]", "pixel_flow"),
                            ("uint32_t", "integration_timespan_us"), ("uint8_t", "quality")],
    "actuator_motors": [("uint64_t", "timestamp_sample"), ("float[12]", "control"),
                        ("uint16_t", "reversible_flags")],
    "actuator_outputs": [("uint32_t", "noutputs"), ("float[16]", "output")],
    # The model's battery and propulsion truth, for thrust-stand and sensor-noise tests
    # (battery fields as PX4's battery_status; the propulsion topic is the rig's own: one
    # entry per rotor of the largest vehicle, NaN past the vehicle's own).
    "battery_status_groundtruth": [("float", "voltage_v"), ("float", "current_a")],
    "rig_propulsion_groundtruth": [(f"float[{MAX_ROTORS}]", "rotor_speed_radps"),
                                   (f"float[{MAX_ROTORS}]", "thrust_n"),
                                   ("float[3]", "force_frd_n"), ("float[3]", "moment_frd_nm")],
}  # fmt: skip

#: Ground-truth snapshots written at once: numpy fills a block's fields in a fraction of
#: the time row-by-row packing took (five topics every frame at 250 Hz), and a block is
#: 0.26 s of truth at the rig's 250 Hz, well inside the writer's flush interval.
TRUTH_BLOCK = 64
#: ``distance_sensor`` constants (PX4 msg/DistanceSensor.msg): MAV_DISTANCE_SENSOR_LASER,
#: ROTATION_DOWNWARD_FACING.
_LASER, _DOWNWARD_FACING = 0, 25
#: ``actuator_motors.control`` and ``actuator_outputs.output`` lengths (PX4 msg/*.msg).
_CONTROLS, _OUTPUTS = 12, 16


class RigLog:
    """Typed writers over :class:`rig.logs.ulog_writer.ULogWriter` for the rig's topics."""

    def __init__(
        self,
        path: Path,
        *,
        info: Mapping[str, str],
        parameters: Mapping[str, int | float],
        home_lat_deg: float,
        home_lon_deg: float,
        home_alt_m: float,
    ) -> None:
        self.writer = ULogWriter(path, TOPICS, info=info, parameters=parameters)
        self.path = self.writer.path
        self._home = (home_lat_deg, home_lon_deg, home_alt_m)
        self._truths: list[tuple[int, VehicleTruth]] = []
        #: The last written snapshot's time and rates (the next one's rate derivative).
        self._last: tuple[int, np.ndarray] | None = None
        self._errors = {"ist8310": 0, "ms5611": 0, "mpu6000": 0, "lidarlite": 0, "pmw3901": 0}
        self._rows: dict[str, Callable[..., None]] = {}

    def _row(self, topic: str) -> Callable[..., None]:
        """The row writer of a topic logged every frame (subscribed when first written)."""
        write = self._rows.get(topic)
        if write is None:
            write = self._rows[topic] = self.writer.row_writer(topic)
        return write

    def truth(self, time_us: int, truth: VehicleTruth) -> None:
        """Ground truth at ``time_us``: gathered, and written :data:`TRUTH_BLOCK` at a time
        (and at :meth:`close`)."""
        self._truths.append((time_us, truth))
        if len(self._truths) == TRUTH_BLOCK:
            self._write_truths()

    def _write_truths(self) -> None:
        """The gathered snapshots as the five ground-truth topics, a field at a time."""
        if not self._truths:
            return
        times_us = np.array([time_us for time_us, _ in self._truths], dtype=np.int64)
        truths = [truth for _, truth in self._truths]
        self._truths = []

        def column(name: str) -> np.ndarray:
            return np.array([getattr(truth, name) for truth in truths])

        q, rates = column("attitude_quat"), column("angular_rate_frd_radps")
        # d(rate)/dt since the snapshot before: zero at a repeated time, so for the first
        # snapshot of the run (it stands in for the one before it)
        last_us, last_rates = self._last or (int(times_us[0]), rates[0])
        previous = np.vstack((last_rates, rates[:-1]))
        dt_s = np.diff(times_us, prepend=last_us) / 1e6
        moved = dt_s > 0
        derivative = np.zeros_like(rates)
        derivative[moved] = (rates[moved] - previous[moved]) / dt_s[moved, None]
        self._last = (int(times_us[-1]), rates[-1])

        records = self.writer.records
        attitude = records("vehicle_attitude_groundtruth", len(truths))
        attitude["q"] = q
        position = records("vehicle_local_position_groundtruth", len(truths))
        position["ref_lat"], position["ref_lon"], position["ref_alt"] = self._home
        for axes, name in ((("x", "y", "z"), "position_ned_m"),
                           (("vx", "vy", "vz"), "velocity_ned_mps"),
                           (("ax", "ay", "az"), "acceleration_ned_mps2")):  # fmt: skip
            for axis, values in zip(axes, column(name).T, strict=True):
                position[axis] = values
        position["heading"] = yaw_from_quat(q)
        for valid in ("xy_valid", "z_valid", "v_xy_valid", "v_z_valid"):
            position[valid] = True
        rate = records("vehicle_angular_velocity_groundtruth", len(truths))
        rate["xyz"], rate["xyz_derivative"] = rates, derivative
        for sampled in (attitude, position, rate):
            sampled["timestamp_sample"] = times_us
        battery = records("battery_status_groundtruth", len(truths))
        battery["voltage_v"] = column("battery_voltage_v")
        battery["current_a"] = column("battery_current_a")
        propulsion = records("rig_propulsion_groundtruth", len(truths))
        rotors = truths[0].rotor_speed_radps.size  # NaN past the vehicle's own rotors
        for field, name in (("rotor_speed_radps", "rotor_speed_radps"),
                            ("thrust_n", "rotor_thrust_n")):  # fmt: skip
            propulsion[field] = math.nan
            propulsion[field][:, :rotors] = column(name)
        propulsion["force_frd_n"] = column("force_frd_n")
        propulsion["moment_frd_nm"] = column("moment_frd_nm")
        for topic, rows in (("vehicle_attitude_groundtruth", attitude),
                            ("vehicle_local_position_groundtruth", position),
                            ("vehicle_angular_velocity_groundtruth", rate),
                            ("battery_status_groundtruth", battery),
                            ("rig_propulsion_groundtruth", propulsion)):  # fmt: skip
            rows["timestamp"] = times_us
            self.writer.write_records(topic, rows)

    def imu(
        self, time_us: int, frame_us: int, accel_mps2: Sequence[float], gyro_radps: Sequence[float]
    ) -> None:
        self._row("sensor_combined")(time_us, *gyro_radps, frame_us, 0, *accel_mps2, frame_us,
                                     0, 0)  # fmt: skip

    def bus_error(self, chip: str) -> None:
        """Count a failed transfer: PX4 reports it as the sensor's ``error_count``."""
        self._errors[chip] += 1

    def mag(self, time_us: int, field_gauss: Sequence[float], temperature_degc: float) -> None:
        x, y, z = field_gauss
        self.writer.write("sensor_mag", time_us, timestamp_sample=time_us, device_id=0, x=x, y=y,
                          z=z, temperature=temperature_degc,
                          error_count=self._errors["ist8310"])  # fmt: skip

    def baro(self, time_us: int, reading: tuple[float, float]) -> None:
        self.writer.write("sensor_baro", time_us, timestamp_sample=time_us, device_id=0,
                          pressure=reading[0], temperature=reading[1],
                          error_count=self._errors["ms5611"])  # fmt: skip

    def gps(self, time_us: int, sent_us: int, fix: GpsFix) -> None:
        """A fix as the autopilot got it, at ``time_us``; ``timestamp_sample`` is when the
        receiver sent it (the UART's time between the two)."""
        self.writer.write(
            "sensor_gps", time_us, timestamp_sample=sent_us, latitude_deg=fix.latitude_deg,
            longitude_deg=fix.longitude_deg, altitude_msl_m=fix.altitude_msl_m, eph=fix.eph,
            epv=fix.epv, vel_m_s=fix.vel_m_s, vel_n_m_s=fix.vel_n_m_s, vel_e_m_s=fix.vel_e_m_s,
            vel_d_m_s=fix.vel_d_m_s, cog_rad=fix.cog_rad, fix_type=fix.fix_type,
            vel_ned_valid=fix.vel_ned_valid, satellites_used=fix.satellites_used,
        )  # fmt: skip

    def rangefinder(self, time_us: int, distance_m: float, signal_quality: int,
                    limits_m: tuple[float, float]) -> None:  # fmt: skip
        """A rangefinder reading as PX4's driver publishes it (laser, facing down)."""
        self.writer.write("distance_sensor", time_us, device_id=0, min_distance=limits_m[0],
                          max_distance=limits_m[1], current_distance=distance_m, variance=0.0,
                          signal_quality=signal_quality, type=_LASER,
                          orientation=_DOWNWARD_FACING)  # fmt: skip

    def optical_flow(self, time_us: int, pixel_flow_rad: tuple[float, float],
                     integration_timespan_us: int, quality: int) -> None:  # fmt: skip
        """A flow report as PX4's pmw3901 driver publishes it."""
        self._row("sensor_optical_flow")(time_us, time_us, *pixel_flow_rad,
                                         integration_timespan_us, quality)  # fmt: skip

    def motors(self, time_us: int, commanded_us: int, controls: Sequence[float]) -> None:
        unused = (math.nan,) * (_CONTROLS - len(controls))
        self._row("actuator_motors")(time_us, commanded_us, *controls, *unused, 0)

    def pwm(self, time_us: int, widths_us: Sequence[float]) -> None:
        unused = (0.0,) * (_OUTPUTS - len(widths_us))
        self._row("actuator_outputs")(time_us, len(widths_us), *widths_us, *unused)

    def event(self, time_us: int, text: str, level: str = "info") -> None:
        self.writer.log(level, time_us, text)

    def close(self) -> None:
        try:
            self._write_truths()
        finally:
            self.writer.close()
