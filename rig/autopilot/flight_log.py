"""The autopilot's ULog: its estimates, set-points and outputs under PX4's uORB names.

Field names are PX4's (``msg/*.msg`` in PX4-Autopilot), so a credibility plan written for a
real flight log reads this one unchanged. Rates follow PX4's logger at least: the rate loop's
topics at up to 250 Hz, the position loop's at 50 Hz. One topic is ours,
``estimator_groundtruth_error``: the estimator against the simulator's truth, which PX4
cannot log because it never sees the truth.
"""

from __future__ import annotations

from pathlib import Path

from rig.ulog import ULogWriter

_SAMPLED = [("uint64_t", "timestamp_sample")]
TOPICS: dict[str, list[tuple[str, str]]] = {
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
    "vehicle_land_detected": [("bool", "landed"), ("bool", "maybe_landed"),
                              ("bool", "ground_contact")],
    "estimator_groundtruth_error": [
        ("float", "attitude_error_rad"), ("float", "tilt_error_rad"),
        ("float", "heading_error_rad"), ("float[3]", "position_error_m"),
        ("float[3]", "velocity_error_m_s"), ("float[3]", "gyro_bias_rad_s"),
    ],
}  # fmt: skip


def open_flight_log(path: str | Path, parameters: dict[str, float | int]) -> ULogWriter:
    """A ULog for the autopilot, with its parameters and PX4-style identity."""
    return ULogWriter(
        path,
        TOPICS,
        info={"sys_name": "hil-rig reference autopilot", "ver_sw": "rig.autopilot",
              "sys_mav_type": "quadrotor"},
        parameters=parameters,
    )  # fmt: skip
