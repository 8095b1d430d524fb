"""The autopilot's ULog: its estimates, set-points and outputs under PX4's uORB names.

Field names are PX4's (``msg/*.msg`` in PX4-Autopilot), so a credibility plan written for a
real flight log reads this one unchanged. Rates follow PX4's logger at least: the rate loop's
topics at up to 250 Hz, the position loop's at 50 Hz. One topic is ours,
``estimator_groundtruth_error``: the estimator against the simulator's truth, which PX4
cannot log because it never sees the truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from rig.logs.ulog_writer import ULogWriter

_SAMPLED = [("uint64_t", "timestamp_sample")]
TOPICS: dict[str, list[tuple[str, str]]] = {
    # PX4 msg/SensorCombined.msg: the IMU averaged over IMU_INTEG_RATE intervals (ImuAverage)
    "sensor_combined": [
        ("float[3]", "gyro_rad"), ("uint32_t", "gyro_integral_dt"),
        ("int32_t", "accelerometer_timestamp_relative"), ("float[3]", "accelerometer_m_s2"),
        ("uint32_t", "accelerometer_integral_dt"), ("uint8_t", "accelerometer_clipping"),
        ("uint8_t", "gyro_clipping"),
    ],
    "vehicle_attitude": [*_SAMPLED, ("float[4]", "q"), ("float[4]", "delta_q_reset"),
                         ("uint8_t", "quat_reset_counter")],
    "vehicle_angular_velocity": [*_SAMPLED, ("float[3]", "xyz"), ("float[3]", "xyz_derivative")],
    "vehicle_local_position": [
        *_SAMPLED, ("bool", "xy_valid"), ("bool", "z_valid"), ("bool", "v_xy_valid"),
        ("bool", "v_z_valid"), ("float", "x"), ("float", "y"), ("float", "z"), ("float", "vx"),
        ("float", "vy"), ("float", "vz"), ("float", "z_deriv"), ("float", "ax"), ("float", "ay"),
        ("float", "az"), ("float", "heading"), ("bool", "xy_global"), ("bool", "z_global"),
        ("double", "ref_lat"), ("double", "ref_lon"), ("float", "ref_alt"), ("float", "eph"),
        ("float", "epv"), ("float", "evh"), ("float", "evv"), ("bool", "dead_reckoning"),
        ("float", "dist_bottom"), ("bool", "dist_bottom_valid"),
    ],
    "vehicle_attitude_setpoint": [("float", "yaw_sp_move_rate"), ("float[4]", "q_d"),
                                  ("float[3]", "thrust_body")],
    "vehicle_rates_setpoint": [("float", "roll"), ("float", "pitch"), ("float", "yaw"),
                               ("float[3]", "thrust_body")],
    "vehicle_local_position_setpoint": [
        ("float", "x"), ("float", "y"), ("float", "z"), ("float", "yaw"), ("float", "yawspeed"),
        ("float", "vx"), ("float", "vy"), ("float", "vz"), ("float[3]", "acceleration"),
        ("float[3]", "thrust"),
    ],
    "vehicle_thrust_setpoint": [*_SAMPLED, ("float[3]", "xyz")],
    "vehicle_torque_setpoint": [*_SAMPLED, ("float[3]", "xyz")],
    "actuator_motors": [*_SAMPLED, ("uint16_t", "reversible_flags"), ("float[12]", "control")],
    "vehicle_status": [
        ("uint64_t", "armed_time"), ("uint8_t", "arming_state"), ("uint8_t", "nav_state"),
        ("uint8_t", "nav_state_user_intention"), ("bool", "failsafe"),
        ("bool", "pre_flight_checks_pass"),
    ],
    # PX4 msg/VehicleOpticalFlowVel.msg, as EKF2 publishes estimator_optical_flow_vel
    "estimator_optical_flow_vel": [
        *_SAMPLED, ("float[2]", "vel_body"), ("float[2]", "vel_ne"),
        ("float[2]", "flow_uncompensated_integral"), ("float[2]", "flow_compensated_integral"),
        ("float[3]", "gyro_rate"), ("float[3]", "gyro_rate_integral"),
    ],
    "vehicle_land_detected": [("bool", "landed"), ("bool", "maybe_landed"),
                              ("bool", "ground_contact")],
    "estimator_groundtruth_error": [
        ("float", "attitude_error_rad"), ("float", "tilt_error_rad"),
        ("float", "heading_error_rad"), ("float[3]", "position_error_m"),
        ("float[3]", "velocity_error_m_s"), ("float[3]", "gyro_bias_rad_s"),
    ],
}  # fmt: skip


@dataclass(frozen=True)
class ImuInterval:
    """One ``sensor_combined`` sample: the IMU's mean over one integration interval."""

    time_us: int  # the last sample of the interval
    gyro_radps: NDArray[np.float64]
    accel_mps2: NDArray[np.float64]
    integral_dt_us: int


class ImuAverage:
    """PX4's ``vehicle_imu`` integrator as ``sensor_combined`` shows it.

    PX4 integrates the raw gyro and accelerometer samples until ``1/IMU_INTEG_RATE`` has
    passed, then publishes integral/Δt: the interval's mean. Real logs hold this stream, not
    the raw samples, so white noise of σ per sample shows as σ/√(samples per interval); a
    simulated log compares only after the same averaging. Each sample counts for the time
    since the previous one (rectangle rule, as PX4's ``Integrator::put``); the first sample
    only starts the clock. An interval closes at the first sample that completes it, with
    half a sample of slack, so 1 kHz samples make exact 5-sample blocks at 200 Hz.
    """

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.interval_us = 1e6 / rate_hz
        self._last_us: int | None = None
        self._reset()

    def _reset(self) -> None:
        self._gyro = np.zeros(3)
        self._accel = np.zeros(3)
        self._dt_us = 0

    def add(
        self, time_us: int, gyro_radps: NDArray[np.float64], accel_mps2: NDArray[np.float64]
    ) -> ImuInterval | None:
        """Add one sample; returns the interval it completes, if any."""
        last, self._last_us = self._last_us, time_us
        if last is None or time_us <= last:
            return None
        dt_us = time_us - last
        self._gyro += gyro_radps * dt_us
        self._accel += accel_mps2 * dt_us
        self._dt_us += dt_us
        if self._dt_us + dt_us / 2 < self.interval_us:
            return None
        interval = ImuInterval(
            time_us, self._gyro / self._dt_us, self._accel / self._dt_us, self._dt_us
        )
        self._reset()
        return interval


def open_flight_log(path: str | Path, parameters: dict[str, float | int]) -> ULogWriter:
    """A ULog for the autopilot, with its parameters and PX4-style identity."""
    return ULogWriter(
        path,
        TOPICS,
        info={"sys_name": "hil-rig reference autopilot", "ver_sw": "rig.autopilots.reference",
              "sys_mav_type": "quadrotor"},
        parameters=parameters,
    )  # fmt: skip
