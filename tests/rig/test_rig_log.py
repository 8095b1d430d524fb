"""rig.ulg's per-frame rows: built in field order by RigLog, checked against the writer's
by-name path (a value in the wrong slot would land in another field)."""

import math

import numpy as np
from pyulog import ULog

from quad_model import QuadModel, load_vehicle
from quad_model.frames import yaw_from_quat
from rig.logs.rig_log import TOPICS, TRUTH_BLOCK, RigLog
from rig.logs.ulog_writer import ULogWriter

HOME = (47.397742, 8.545594, 488.0)


def _fields(path, topic):
    data = ULog(str(path), [topic]).get_dataset(topic).data
    return {name: values for name, values in data.items()}


def test_every_frame_row_matches_the_by_name_write(tmp_path):
    model = QuadModel(load_vehicle("f450_high_precision"), np.random.default_rng(3))
    model.reset(position_ned_m=(1.0, -2.0, -3.0), rotor_speed_radps=(400, 410, 420, 430))
    log = RigLog(tmp_path / "rows.ulg", info={}, parameters={}, home_lat_deg=HOME[0],
                 home_lon_deg=HOME[1], home_alt_m=HOME[2])  # fmt: skip
    expected = ULogWriter(tmp_path / "names.ulg", TOPICS)
    previous = None
    # Past a block of truth (written at once), with a repeated time at the block's edge.
    times = [frame * 4000 for frame in range(1, TRUTH_BLOCK + 4)]
    times[TRUTH_BLOCK] = times[TRUTH_BLOCK - 1]
    for frame, t in enumerate(times, start=1):
        model.advance(np.array([0.6, 0.5, 0.55, 0.45]), 0.004)
        truth = model.truth
        accel, gyro = (0.1 * frame, -0.2, -9.8), (0.01, 0.02 * frame, -0.03)
        controls, widths = (0.5, 0.6, 0.7, 0.8), (1500.0, 1600.0, 1700.0, 1800.0)
        log.truth(t, truth)
        log.imu(t, 4000, accel, gyro)
        log.motors(t, t - 100, controls)
        log.pwm(t, widths)
        log.optical_flow(t, (0.01 * frame, -0.02), 20_000, 200)

        rates = truth.angular_rate_frd_radps
        moved = previous is not None and t > previous[0]
        derivative = (rates - previous[1]) / ((t - previous[0]) / 1e6) if moved else np.zeros(3)
        previous = (t, rates)
        q = truth.attitude_quat
        p, v, a = truth.position_ned_m, truth.velocity_ned_mps, truth.acceleration_ned_mps2
        expected.write("vehicle_attitude_groundtruth", t, timestamp_sample=t, q=q,
                       delta_q_reset=np.zeros(4), quat_reset_counter=0)  # fmt: skip
        expected.write(
            "vehicle_local_position_groundtruth", t, timestamp_sample=t, ref_lat=HOME[0],
            ref_lon=HOME[1], ref_alt=HOME[2], x=p[0], y=p[1], z=p[2], vx=v[0], vy=v[1], vz=v[2],
            ax=a[0], ay=a[1], az=a[2], heading=yaw_from_quat(q), xy_valid=True, z_valid=True,
            v_xy_valid=True, v_z_valid=True,
        )  # fmt: skip
        expected.write("vehicle_angular_velocity_groundtruth", t, timestamp_sample=t, xyz=rates,
                       xyz_derivative=derivative)  # fmt: skip
        expected.write("battery_status_groundtruth", t, voltage_v=truth.battery_voltage_v,
                       current_a=truth.battery_current_a)  # fmt: skip
        no_rotors = [math.nan] * 4  # a quad: rotors 4..7 of the topic are NaN
        expected.write("rig_propulsion_groundtruth", t,
                       rotor_speed_radps=[*truth.rotor_speed_radps, *no_rotors],
                       thrust_n=[*truth.rotor_thrust_n, *no_rotors], force_frd_n=truth.force_frd_n,
                       moment_frd_nm=truth.moment_frd_nm)  # fmt: skip
        expected.write("sensor_combined", t, gyro_rad=gyro, gyro_integral_dt=4000,
                       accelerometer_timestamp_relative=0, accelerometer_m_s2=accel,
                       accelerometer_integral_dt=4000, accelerometer_clipping=0,
                       gyro_clipping=0)  # fmt: skip
        expected.write("actuator_motors", t, timestamp_sample=t - 100,
                       control=list(controls) + [math.nan] * 8, reversible_flags=0)  # fmt: skip
        expected.write("actuator_outputs", t, noutputs=4, output=list(widths) + [0.0] * 12)
        expected.write("sensor_optical_flow", t, timestamp_sample=t,
                       pixel_flow=[0.01 * frame, -0.02], integration_timespan_us=20_000,
                       quality=200)  # fmt: skip
    log.close()
    expected.close()

    for topic in TOPICS:
        if topic in ("sensor_mag", "sensor_baro", "sensor_gps", "distance_sensor"):
            continue  # written by name in RigLog too
        got, want = _fields(tmp_path / "rows.ulg", topic), _fields(tmp_path / "names.ulg", topic)
        assert got.keys() == want.keys(), topic
        for name in want:
            np.testing.assert_array_equal(got[name], want[name], err_msg=f"{topic}.{name}")
