"""px4_logs: the one reader of PX4 logs, on in-memory logs with known answers and on the real
X500 flight."""

from pathlib import Path

import numpy as np
import pytest

from px4_logs import FlightLog, LogError, motor_pwm_range
from px4_logs.flight_log import HOVER_MAX_SPEED_MPS, MIN_HOVER_S


def _log(**topics: dict) -> FlightLog:
    return FlightLog("synthetic.ulg", topics, {})


def _us(seconds) -> np.ndarray:
    return np.asarray(seconds, dtype=float) * 1e6


def test_a_value_in_force_at_a_time_is_the_last_sample_at_or_before_it():
    log = _log(battery_status={"timestamp": _us([1.0, 2.0, 3.0]), "voltage_v": [16.0, 15.5, 15.0]})
    assert log.value_at("battery_status", "voltage_v", 0.5, "why") == 16.0  # before: the first
    assert log.value_at("battery_status", "voltage_v", 2.0, "why") == 15.5  # at a sample
    assert log.value_at("battery_status", "voltage_v", 2.9, "why") == 15.5
    assert log.value_at("battery_status", "voltage_v", 9.0, "why") == 15.0
    assert (log.first_s, log.last_s) == (1.0, 3.0)


def test_what_a_tool_can_do_without_is_none_and_what_it_needs_is_one_line():
    log = _log(battery_status={"timestamp": _us([1.0, 2.0]), "voltage_v": [16.0, np.nan]})
    assert log.logged_at("battery_status", "voltage_v", 2.5) is None  # not finite
    assert log.logged_at("battery_status", "current_a", 2.5) is None
    assert log.logged_at("vehicle_air_data", "rho", 2.5) is None
    with pytest.raises(LogError) as error:
        log.topic("vehicle_air_data", "the air density")
    assert (
        str(error.value)
        == "synthetic.ulg: topic vehicle_air_data (the air density) is not in the log"
    )
    with pytest.raises(LogError, match=r"topic battery_status has no field current_a \(the load\)"):
        log.value_at("battery_status", "current_a", 1.0, "the load")


def test_series_are_time_ordered_with_repeated_stamps_dropped_and_rates_at_their_sample_time():
    """The body rates are placed at ``timestamp_sample`` (when the gyro measured them), so a
    delay fitted from them is physical; a repeated stamp is dropped."""
    log = _log(
        vehicle_angular_velocity={
            "timestamp": _us([1.0, 1.1, 1.2]),
            "timestamp_sample": _us([0.99, 1.09, 1.09]),
            "xyz[0]": [0.1, 0.2, 0.3],
        },
        vehicle_land_detected={"timestamp": _us([2.0, 1.0]), "landed": [0.0, 1.0]},
    )
    time_s, values = log.series("vehicle_angular_velocity", "xyz[0]", "why")
    assert time_s == pytest.approx([0.99, 1.09])
    assert values == pytest.approx([0.1, 0.2])
    time_s, landed = log.series("vehicle_land_detected", "landed", "why")
    assert time_s == pytest.approx([1.0, 2.0])  # sorted by time
    assert landed.tolist() == [1.0, 0.0]


def test_spans_airborne_and_armed():
    t = np.arange(0.0, 100.0, 0.5)
    land = {"timestamp": _us(t), "landed": ((t < 20.0) | (t >= 80.0)).astype(float)}
    armed = {"timestamp": _us(t), "armed": ((t >= 10.0) & (t < 90.0)).astype(float)}
    assert _log(vehicle_land_detected=land).airborne_span() == (20.0, 79.5)
    assert _log(vehicle_land_detected=land, actuator_armed=armed).armed_span() == (10.0, 90.0, True)
    # without actuator_armed the airborne span, not ended by a logged disarm
    assert _log(vehicle_land_detected=land).armed_span() == (20.0, 79.5, False)
    grounded = {"timestamp": _us(t), "landed": np.ones(t.size)}
    with pytest.raises(LogError, match=r"synthetic\.ulg: the vehicle never left the ground"):
        _log(vehicle_land_detected=grounded).airborne_span()


def _hover_log(speed_mps: float) -> FlightLog:
    """60 s at 50 Hz: landed 0-10 s, then airborne moving north at ``speed_mps``."""
    t = np.arange(0.0, 60.0, 0.02)
    stamp, zeros = _us(t), np.zeros(t.size)
    return _log(
        vehicle_local_position={
            "timestamp": stamp,
            "vx": np.full(t.size, speed_mps),
            "vy": zeros,
            "vz": zeros,
        },
        vehicle_land_detected={"timestamp": stamp, "landed": (t < 10.0).astype(float)},
        vehicle_angular_velocity={"timestamp": stamp, **{f"xyz[{i}]": zeros for i in range(3)}},
        vehicle_thrust_setpoint={"timestamp": stamp, "xyz[2]": np.full(t.size, -0.5)},
    )


def test_a_steady_hover_is_found_and_a_transit_is_not():
    (window,) = _hover_log(0.0).hover_windows()
    assert window[0] == pytest.approx(10.0, abs=0.05)
    assert window[1] == pytest.approx(59.98, abs=0.05)
    assert window[1] - window[0] >= MIN_HOVER_S
    assert _hover_log(HOVER_MAX_SPEED_MPS * 1.5).hover_windows() == ()


def test_an_older_layout_is_derived_and_says_so():
    """A PX4 before 1.13 logged the torque and thrust in actuator_controls_0 and before 1.10
    the body rates only in sensor_combined: the newer topics are derived, each with a note."""
    t = _us([1.0, 2.0])
    log = _log(
        actuator_controls_0={
            "timestamp": t,
            **{f"control[{i}]": np.array([0.1, 0.2]) * i for i in range(4)},
        },
        sensor_combined={
            "timestamp": t,
            **{f"gyro_rad[{i}]": np.array([0.01, 0.02]) for i in range(3)},
        },
    )
    assert log.series("vehicle_thrust_setpoint", "xyz[2]", "")[1] == pytest.approx([-0.3, -0.6])
    assert log.series("vehicle_torque_setpoint", "xyz[1]", "")[1] == pytest.approx([0.1, 0.2])
    assert log.series("vehicle_angular_velocity", "xyz[2]", "")[1] == pytest.approx([0.01, 0.02])
    assert len(log.derived) == 3
    assert all("derived from" in note for note in log.derived)


def test_reading_a_file_refuses_in_one_line(tmp_path):
    with pytest.raises(LogError) as missing:
        FlightLog.read(tmp_path / "none.ulg")
    assert str(missing.value) == f"{tmp_path / 'none.ulg'}: flight log not found"
    junk = tmp_path / "junk.ulg"
    junk.write_bytes(b"not a ulog at all")
    with pytest.raises(LogError) as unreadable:
        FlightLog.read(junk)
    assert str(unreadable.value).startswith(f"{junk}: not a readable ULog file")
    assert "\n" not in str(unreadable.value)


def test_the_x500_flight(x500_log: Path):
    """The real flight: its firmware, span, parameters and four hover windows (the wind
    estimate's, tests/rig/test_wind.py)."""
    log = FlightLog.read(x500_log)
    assert log.firmware.startswith("PX4 v1.17")
    assert log.parameters["SYS_AUTOSTART"] == 4019
    assert log.first_s < log.airborne_span()[0] < log.airborne_span()[1] < log.last_s
    assert len(log.hover_windows()) == 4
    assert log.derived == ()  # a current layout


def test_the_motor_outputs_pwm_range():
    """Motor 1..4 (functions 101..104) on AUX with their PWM range; an older PX4's one main
    range; PX4's defaults without either; motors at different ranges refused."""
    aux = {f"PWM_AUX_FUNC{i}": 100 + i for i in range(1, 5)}
    aux |= {f"PWM_AUX_MIN{i}": 1100 for i in range(1, 5)} | {
        f"PWM_AUX_MAX{i}": 1900 for i in range(1, 5)
    }
    assert motor_pwm_range(aux, "log") == (1100.0, 1900.0)
    assert motor_pwm_range({"PWM_MAIN_MIN": 1075, "PWM_MAIN_MAX": 1950}, "log") == (1075.0, 1950.0)
    assert motor_pwm_range({}, "log") == (1000.0, 2000.0)
    with pytest.raises(LogError, match="log: the motor outputs have different PWM ranges"):
        motor_pwm_range(aux | {"PWM_AUX_MAX4": 2000}, "log")
    with pytest.raises(LogError, match=r"log: parameter PWM_AUX_MIN1 is not in the log"):
        motor_pwm_range({"PWM_AUX_FUNC1": 101, "PWM_AUX_MAX1": 1900}, "log")
