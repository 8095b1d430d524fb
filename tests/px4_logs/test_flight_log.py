"""px4_logs: the one reader of PX4 logs, on in-memory logs with known answers and on the real
X500 flight."""

from pathlib import Path

import numpy as np
import pytest

from px4_logs import FlightLog, LogError, OutputProtocol, motor_outputs
from px4_logs.flight_log import AIRBORNE_HEIGHT_M, HOVER_MAX_SPEED_MPS, MIN_HOVER_S


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


def _outputs(parameters: dict, *instances: dict) -> FlightLog:
    return FlightLog("outputs.ulg", {"actuator_outputs": instances} if instances else
                     {"vehicle_status": {"timestamp": _us([1.0])}}, parameters)  # fmt: skip


def _functions(
    prefix: str, count: int, low: float | None = None, high: float | None = None
) -> dict:
    parameters = {f"{prefix}_FUNC{i}": 100 + i for i in range(1, count + 1)}
    if low is not None:
        parameters |= {f"{prefix}_MIN{i}": low for i in range(1, count + 1)}
        parameters |= {f"{prefix}_MAX{i}": high for i in range(1, count + 1)}
    return parameters


def test_each_output_driver_gives_its_range_in_its_unit_and_as_esc_throttle():
    """PWM µs map 1000..2000 to throttle 0..1; the dshot driver (a PWM prefix whose timer is
    DShot) sends DSHOT_MIN·1999 (truncated, as PX4 does) .. 1999 of 1999; UAVCAN's raw
    command MIN..MAX of 8191. An older PX4's one main range; PX4's default without any."""
    pwm = motor_outputs(_outputs(_functions("PWM_AUX", 4, 1100, 1900)))
    assert (pwm.protocol, pwm.unit, pwm.rotor_count) == (OutputProtocol.PWM, "µs", 4)
    assert pwm.output_range == (1100.0, 1900.0)
    assert pwm.throttle_range == pytest.approx((0.1, 0.9), abs=1e-12)
    assert pwm.pwm_range_us == pytest.approx((1100.0, 1900.0), abs=1e-9)
    timers = {"PWM_AUX_TIM0": -3, "PWM_AUX_TIM1": 400, "DSHOT_MIN": 0.15, "CA_ROTOR_COUNT": 8}
    dshot = motor_outputs(_outputs(_functions("PWM_AUX", 8, 1150, 2000) | timers))
    assert (dshot.protocol, dshot.unit, dshot.rotor_count) == (OutputProtocol.DSHOT, "DShot", 8)
    assert dshot.output_range == (299.0, 1999.0)  # int(0.15 · 1999): the PWM limits unused
    assert dshot.throttle_range == pytest.approx((299 / 1999, 1.0))
    assert dshot.channels == tuple(range(8))
    can = motor_outputs(_outputs(_functions("UAVCAN_EC", 4, 819, 7372)))
    assert (can.protocol, can.unit, can.output_range) == (
        OutputProtocol.CAN,
        "CAN raw",
        (819, 7372),
    )
    assert can.throttle_range == pytest.approx((819 / 8191, 7372 / 8191))
    assert can.pwm_range_us == pytest.approx((1000 + 1000 * 819 / 8191, 1000 + 1000 * 7372 / 8191))
    older = motor_outputs(_outputs({"PWM_MAIN_MIN": 1075, "PWM_MAIN_MAX": 1950}))
    assert older.output_range == (1075.0, 1950.0)
    assert "PX4 before 1.13" in older.reason
    assert motor_outputs(_outputs({})).output_range == (1000.0, 2000.0)
    # motors on outputs 3..6, in reverse order: channel of motor 1 first
    swapped = {f"PCA9685_FUNC{7 - m}": 100 + m for m in range(1, 5)}
    swapped |= {
        f"PCA9685_{k}{i}": v for i in range(3, 7) for k, v in (("MIN", 1000), ("MAX", 2000))
    }
    assert motor_outputs(_outputs(swapped)).channels == (5, 4, 3, 2)


def test_motor_outputs_that_cannot_be_read_are_one_line():
    aux = _functions("PWM_AUX", 4, 1100, 1900)
    gap = {"PWM_MAIN_FUNC1": 101, "PWM_MAIN_FUNC2": 103}
    cases = [
        (aux | {"PWM_AUX_MAX4": 2000}, "the motor outputs have different ranges"),
        ({"PWM_AUX_FUNC1": 101, "PWM_AUX_MAX1": 1900}, "parameter PWM_AUX_MIN1 is not in the log"),
        (aux | {"UAVCAN_EC_FUNC1": 105}, r"the motors are spread over the output drivers \["),
        (gap, "no PWM_MAIN_FUNCn is Motor 2"),
    ]
    for parameters, message in cases:
        with pytest.raises(LogError, match=f"^outputs.ulg: {message}") as error:
            motor_outputs(_outputs(parameters))
        assert "\n" not in str(error.value)


def _can_instances(t: np.ndarray) -> tuple[dict, dict, dict]:
    """Thrust 0.3..0.7; instance 0 all zero (a PWM driver with nothing on it), instance 1 the
    UAVCAN ESCs at raw = 819 + (7372 − 819)·thrust on channels 0-3."""
    thrust = 0.5 + 0.2 * np.sin(t)
    raw = 819 + (7372 - 819) * thrust
    zeros = {"timestamp": _us(t), **{f"output[{i}]": np.zeros(t.size) for i in range(8)}}
    motors = {"timestamp": _us(t), **{f"output[{i}]": raw for i in range(4)}}
    return {"timestamp": _us(t), "xyz[2]": -thrust}, zeros, motors


def test_the_instance_whose_motor_channels_follow_the_thrust_carries_the_motors():
    """Known answer: the motors are instance 1 (UAVCAN); an all-zero instance 0 and a servo
    instance moving against the thrust do not win; an older layout's actuator_motors is
    derived from that instance through its range, not from instance 0."""
    t = np.arange(0.0, 20.0, 0.1)
    thrust, zeros, motors = _can_instances(t)
    servo = {"timestamp": _us(t), **{f"output[{i}]": 1500 - 100 * np.sin(t) for i in range(4)}}
    parameters = _functions("UAVCAN_EC", 4, 819, 7372)
    log = FlightLog("can.ulg", {"actuator_outputs": (zeros, motors, servo),
                                "vehicle_thrust_setpoint": thrust}, parameters)  # fmt: skip
    outputs = motor_outputs(log)
    assert outputs.instance == 1
    assert "0: constant" in outputs.reason
    assert "1: r = 1.00" in outputs.reason
    assert len(log.instances("actuator_outputs")) == 3
    older = FlightLog(
        "older.ulg",
        {"actuator_outputs": (zeros, motors),
         "actuator_controls_0": {"timestamp": _us(t), **{f"control[{i}]": np.zeros(t.size)
                                                        for i in range(3)},
                                 "control[3]": -thrust["xyz[2]"]}},
        {"PWM_MAIN_MIN": 819, "PWM_MAIN_MAX": 7372, "CA_ROTOR_COUNT": 4},
    )  # fmt: skip
    for motor in range(4):
        commands = older.series("actuator_motors", f"control[{motor}]", "")[1]
        assert commands == pytest.approx(-thrust["xyz[2]"], abs=1e-9)
    nothing = FlightLog("zeros.ulg", {"actuator_outputs": (zeros,)}, parameters)
    assert motor_outputs(nothing).instance is None
    assert "no actuator_outputs instance moves" in motor_outputs(nothing).reason


def test_the_escs_measured_speeds_per_motor_in_rad_per_s():
    """esc_rpm → rad/s, ESC i placed at the motor its actuator_function names (here reversed);
    a second instance of ESCs reporting no speed (zeros) is passed over; without speeds, None."""
    t = np.arange(0.0, 2.0, 0.5)
    silent = {"timestamp": _us(t), **{f"esc[{i}].esc_rpm": np.zeros(t.size) for i in range(4)}}
    reporting = {"timestamp": _us(t)}
    for esc in range(4):
        reporting[f"esc[{esc}].esc_rpm"] = np.full(t.size, 6000.0 + 100 * esc)
        reporting[f"esc[{esc}].actuator_function"] = np.full(t.size, 104 - esc)
    log = FlightLog("esc.ulg", {"esc_status": (silent, reporting)}, {"CA_ROTOR_COUNT": 4})
    time_s, speeds = log.rotor_speeds()
    assert time_s == pytest.approx(t)
    expected = np.array([6300.0, 6200.0, 6100.0, 6000.0]) * 2 * np.pi / 60
    np.testing.assert_allclose(speeds, np.tile(expected, (t.size, 1)))
    assert FlightLog("esc.ulg", {"esc_status": silent}, {}).rotor_speeds() is None
    assert _log(battery_status={"timestamp": _us(t)}).rotor_speeds() is None


def _no_detector(t: np.ndarray, height: bool) -> FlightLog:
    """Armed 5-55 s; climbs at 1 m/s from 10 s to 10 m, descends at 1 m/s from 45 s (ground
    at z = −3 m: a baro's offset), thrust 0.6 while climbing or flying, 0.1 on the ground."""
    flying = (t >= 10.0) & (t < 55.0)
    height_m = np.clip(np.minimum(t - 10.0, 55.0 - t), 0.0, 10.0)
    topics = {
        "actuator_armed": {"timestamp": _us(t), "armed": ((t >= 5.0) & (t < 58.0)).astype(float)},
        "vehicle_thrust_setpoint": {"timestamp": _us(t), "xyz[2]": np.where(flying, -0.6, -0.1)},
    }
    if height:
        topics["vehicle_local_position"] = {"timestamp": _us(t), "z": -3.0 - height_m}
    return FlightLog("no_detector.ulg", topics, {})


def test_without_a_land_detector_the_span_comes_from_arming_and_height_or_thrust():
    """Known answers: by height, airborne from AIRBORNE_HEIGHT_M above the armed ground level
    (10.5 s at 1 m/s) to the last sample above it; by thrust, where it passes 0.8 of the
    hover level; each says how in ``derived``; without an arming state one line."""
    t = np.arange(0.0, 60.0, 0.05)
    by_height = _no_detector(t, height=True)
    start, end = by_height.airborne_span()
    assert start == pytest.approx(10.0 + AIRBORNE_HEIGHT_M, abs=0.06)
    assert end == pytest.approx(55.0 - AIRBORNE_HEIGHT_M, abs=0.06)
    assert "vehicle_local_position.z" in by_height.derived[-1]
    by_thrust = _no_detector(t, height=False)
    assert by_thrust.airborne_span() == pytest.approx((10.0, 54.95), abs=1e-6)
    assert "thrust set-point" in by_thrust.derived[-1]
    bare = _log(vehicle_thrust_setpoint={"timestamp": _us(t), "xyz[2]": -np.ones(t.size)})
    with pytest.raises(LogError) as error:
        bare.airborne_span()
    assert str(error.value) == (
        "synthetic.ulg: no vehicle_land_detected, and no arming state (actuator_armed, "
        "vehicle_status) to derive the airborne span from"
    )


def test_the_x500_flight_without_its_land_detector(x500_log: Path):
    """The real flight with vehicle_land_detected removed: the span from arming and height is
    within 2 s of the detector's at either end (a 0.5 m climb-out), from arming and thrust
    too, and the four hover windows are the detector's."""
    log = FlightLog.read(x500_log)
    detector = log.airborne_span()
    for dropped in (
        ("vehicle_land_detected",),
        ("vehicle_land_detected", "vehicle_local_position"),
    ):
        topics = {name: log.instances(name) for name in log.topics if name not in dropped}
        derived = FlightLog(log.path, topics, log.parameters)
        assert derived.airborne_span() == pytest.approx(detector, abs=2.0)
        assert derived.derived[-1].startswith("airborne span derived")
        if "vehicle_local_position" in derived.topics:
            assert derived.hover_windows() == log.hover_windows()


def test_the_x8_octo_runs_its_motors_on_dshot(auriol_log: Path):
    """The X8's log: Motor 1..8 on PWM_AUX whose timers 0-7 are DShot600 (−3), DSHOT_MIN
    0.15, no actuator_outputs logged; no land detector and no arming state, so its airborne
    span is one line saying so."""
    log = FlightLog.read(auriol_log)
    outputs = motor_outputs(log)
    assert (outputs.protocol, outputs.rotor_count, outputs.instance) == (
        OutputProtocol.DSHOT, 8, None,
    )  # fmt: skip
    assert outputs.output_range == (299.0, 1999.0)
    assert "actuator_outputs not logged" in outputs.reason
    with pytest.raises(LogError, match="no vehicle_land_detected, and no arming state"):
        log.airborne_span()
