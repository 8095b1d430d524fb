"""``rig replay``: a real PX4 flight's own setpoints flown through the rig.

The plan is checked against the real X500 log's facts (its timeline in
data/flight_logs/README.md, and the log itself where that rounds); the flights are short
spans of that log: the take-off (velocity drive), a one-second rates window and a
one-second attitude window during the climb.
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import pyulog

from px4_logs import FlightLog, LogError
from quad_model.environment import DRY_AIR_GAS_CONSTANT, isa_pressure_pa, isa_temperature_k
from quad_model.frames import quat_multiply
from quad_model.vehicle import load_vehicle
from rig.chips.pwm import PwmOutput
from rig.cli import main
from rig.identify import IdentificationError, identify_vehicle
from rig.lockstep.loop import RunOptions
from rig.logs.ulog_writer import ULogWriter
from rig.replay import ReplayError, ReplayOptions, plan_replay, run_replay
from tests.instances import free_test_instance

#: The X500 log's first timestamp (a stale config_overrides sample the logger wrote first).
X500_FIRST_S = 407.404345
#: PX4 logs from arming (SDLOG_MODE 0): "Armed by RC switch" at 408.889 s and
#: vehicle_status.armed_time = 408.889359 s. The README's timeline rounds the armed span to "407.4",
#: the log's first timestamp.
X500_ARMED_S = 408.889359
#: The climb window: vz_sp = -1.5 m/s from 413.8 to 417.2 s, airborne (README: 413-419).
CLIMB_WINDOW_S = (415.0, 416.0)


@pytest.fixture(scope="module")
def x500_path() -> Path:
    return (
        Path(__file__).resolve().parents[2]
        / "data/flight_logs"
        / ("px4_x500v2_v6xrt_flight_2026-03-20.ulg")
    )


@pytest.fixture(scope="module")
def real_log(x500_path):
    return pyulog.ULog(str(x500_path), [
        "vehicle_local_position", "vehicle_local_position_setpoint", "vehicle_rates_setpoint",
        "vehicle_attitude_setpoint", "vehicle_thrust_setpoint",
    ])  # fmt: skip


def _fly(x500_path: Path, out: Path, instance: int, **options) -> tuple[pyulog.ULog, pyulog.ULog]:
    plan = plan_replay(x500_path, ReplayOptions(seed=5, **options))
    result = run_replay(plan, RunOptions(instance=instance, out_dir=out))
    return pyulog.ULog(str(result.rig_log)), pyulog.ULog(str(result.autopilot_log))


@pytest.fixture(scope="module")
def takeoff(x500_path, tmp_path_factory):
    """407.4 → 420 s with the velocity drive: armed idle, the vz_sp step, the climb."""
    out = tmp_path_factory.mktemp("takeoff")
    return out, *_fly(x500_path, out, free_test_instance(), end_s=420.0)


# -- the plan ---------------------------------------------------------------------------------


def test_plan_reads_the_x500_configuration_from_its_log(x500_path):
    plan = plan_replay(x500_path)
    assert plan.vehicle == "x500_v2"
    assert plan.vehicle_reason == "SYS_AUTOSTART = 4019"
    assert plan.cell_count == 4
    assert plan.vehicle_document["battery"]["cell_count"] == 4
    assert plan.parameters["MC_ROLLRATE_P"] == pytest.approx(0.14, abs=1e-7)
    assert plan.parameters["IMU_GYRO_CUTOFF"] == 30.0
    assert plan.parameters["IMU_INTEG_RATE"] == 200
    assert "MC_ROLLRATE_P=0.14000000059604645" in plan.autopilot_params  # the float32, exact
    assert "MAV_SYS_ID" not in plan.parameters  # the rig's instance decides it
    assert plan.skipped == ()
    assert plan.unknown_parameter_count > 900
    assert plan.start_s == pytest.approx(X500_FIRST_S, abs=1e-6)
    assert plan.end_s == pytest.approx(504.1, abs=0.05)  # README: log ends at 504.1
    assert plan.real_arm_s == pytest.approx(X500_ARMED_S, abs=1e-3)
    assert plan.arm_s == plan.real_arm_s  # 1.5 s after the start: the autopilot is ready
    assert plan.disarm_s == pytest.approx(503.1, abs=0.05)  # README: disarmed at 503.1
    # heading 1.716 rad at the start; EKF2's in-flight alignment at 415.14 s, 2 s after the
    # take-off, moved it by +0.1554 rad: the vehicle starts at the corrected heading
    ((reset_s, delta),) = plan.heading_resets
    assert reset_s == pytest.approx(415.14, abs=0.01)
    assert delta == pytest.approx(0.1554, abs=1e-4)
    assert math.degrees(plan.yaw_rad) == pytest.approx(98.3 + 8.9, abs=0.1)
    assert plan.summary()["heading_resets"] == [
        {"time_s": reset_s, "delta_deg": pytest.approx(8.90, abs=0.01)}
    ]
    # the yaw set-points logged before the reset are turned into the corrected frame too
    yaw = np.array(plan.tracks["velocity"].values)[:, 3]
    track_s = plan.start_s + np.array(plan.tracks["velocity"].times_s)
    logged = pyulog.ULog(str(x500_path), ["vehicle_local_position_setpoint"]).data_list[0].data
    logged_s, logged_yaw = logged["timestamp"] / 1e6, logged["yaw"]
    for at_s, turned in ((414.5, delta), (416.0, 0.0)):
        k = np.searchsorted(track_s, at_s)
        j = np.argmin(np.abs(logged_s - track_s[k]))  # the same sample, without rounding
        assert yaw[k] == pytest.approx(logged_yaw[j] + turned, abs=1e-5)
    assert plan.home.lat_deg == pytest.approx(51.901, abs=1e-3)
    track = plan.tracks["velocity"]
    times_s = plan.start_s + np.array(track.times_s)
    vz = np.array(track.values)[:, 2]
    assert times_s[np.argmax(vz <= -1.0)] == pytest.approx(413.0, abs=0.5)  # README: 413
    assert vz[0] == 0.0  # NaN before take-off: held at rest
    assert [c.action for c in plan.commands] == ["arm", "track", "disarm"]
    # the log's one bit-rotted message (README) is reported, not swallowed
    (warning,) = plan.log_warnings
    assert "no subscription found for message id 32812" in warning
    assert ("warn", f"replay: {warning}") in plan.notes
    # the motor outputs PWM_AUX_FUNC1..4 = 101..104 span PWM_AUX_MIN/MAX = 1100..1900 µs
    assert plan.motor_pwm_range_us == (1100.0, 1900.0)
    assert plan.scenario(Path("x500_v2")).motor_pwm_range_us == (1100.0, 1900.0)
    # the pack at rest before arming: battery_status.voltage_v = 15.19 V (not full 16.8 V)
    assert plan.initial_battery_voltage_v == pytest.approx(15.2, abs=0.2)
    assert plan.scenario(Path("x500_v2")).start.battery_voltage_v == (
        plan.initial_battery_voltage_v
    )
    summary = plan.summary()
    assert summary["motor_pwm_range_us"] == [1100.0, 1900.0]
    assert summary["initial_battery_voltage_v"] == plan.initial_battery_voltage_v


def test_pwm_output_maps_commands_onto_the_motor_range():
    out = PwmOutput(2, 400, (1100.0, 1900.0))
    out.command([0.0, 0.5], armed=True)
    assert [p.width_us for p in out.pulses(1)] == [1100, 1500]  # idle at command 0
    out.command([1.0, 1.2], armed=True)  # clamped, as pwm_out does
    assert [p.width_us for p in out.pulses(2501)] == [1900, 1900]
    out.command([0.7, 0.7], armed=False)
    assert [p.width_us for p in out.pulses(5001)] == [1000, 1000]  # PWM_*_DISn
    with pytest.raises(ValueError, match=r"range_us must satisfy 1000 <= min < max <= 2000"):
        PwmOutput(1, 400, (1900.0, 1100.0))


def test_log_without_battery_or_motor_outputs_keeps_the_defaults(tmp_path):
    plan = plan_replay(_synthetic_log(tmp_path / "d.ulg", {"SYS_AUTOSTART": 4019}))
    assert plan.motor_pwm_range_us == (1000.0, 2000.0)  # PX4's PWM_MAIN_MIN/MAX defaults
    assert plan.initial_battery_voltage_v is None
    assert ("warn", "replay: the battery starts full (no battery_status in the log)") in (
        plan.notes
    )


def test_bad_battery_and_pwm_configurations_fail_with_one_line(tmp_path):
    flat = _synthetic_log(tmp_path / "b.ulg", {"SYS_AUTOSTART": 4019}, battery_v=12.1)
    assert _error(flat) == (
        f"{flat}: battery_status.voltage_v at --start 100 s: battery_voltage_v=12.1 V is "
        "outside the pack's open-circuit range 14..16.8 V (4 cells × 3.5..4.2 V)"
    )
    motors = {"SYS_AUTOSTART": 4019, "PWM_AUX_FUNC1": 101, "PWM_AUX_FUNC2": 102,
              "PWM_AUX_MIN1": 1100, "PWM_AUX_MAX1": 1900}  # fmt: skip
    missing = _synthetic_log(tmp_path / "m.ulg", motors)
    assert _error(missing) == (
        f"{missing}: parameter PWM_AUX_MIN2 is not in the log (PWM_AUX_FUNC2 = 102 is a "
        "motor output)"
    )
    mixed = _synthetic_log(
        tmp_path / "x.ulg", {**motors, "PWM_AUX_MIN2": 1000, "PWM_AUX_MAX2": 1900}
    )
    assert _error(mixed) == (
        f"{mixed}: the motor outputs have different ranges [(1000.0, 1900.0), (1100.0, 1900.0)]"
    )


def test_plan_flies_the_logs_air_and_wind(x500_path):
    """The log's air density (vehicle_air_data.rho, 1.169 kg/m³ at 184 m: a warm day) becomes
    the ISA temperature offset that gives it at home, and the hover-tilt wind (rig.identify.wind)
    the steady wind with Dryden turbulence at W20 = its speed; replay.json says both."""
    plan = plan_replay(x500_path)
    assert plan.air_density_kgpm3 == pytest.approx(1.169, abs=0.002)
    scenario = plan.scenario(Path("x500_v2"))
    env = scenario.environment
    assert env.temperature_offset_k == pytest.approx(plan.temperature_offset_k)
    altitude = env.home.alt_amsl_m
    temperature = isa_temperature_k(altitude) + env.temperature_offset_k
    density = isa_pressure_pa(altitude) / (DRY_AIR_GAS_CONSTANT * temperature)
    assert density == pytest.approx(plan.air_density_kgpm3, rel=1e-9)
    assert env.wind.steady_ned_mps == plan.wind.steady_ned_mps
    assert env.wind.wind_at_6m_mps == pytest.approx(plan.wind.speed_mps)
    summary = plan.summary()
    assert summary["temperature_offset_k"] == pytest.approx(8.4, abs=0.3)
    assert summary["wind"]["bound_mps"] == plan.wind.bound_mps
    assert any("air density 1.169 kg/m³ as logged" in text for _, text in plan.notes)


def test_plan_window_switches_drives_and_back(x500_path):
    plan = plan_replay(x500_path, ReplayOptions(drive="rates", window_s=CLIMB_WINDOW_S))
    kinds = [(c.action, c.track.kind if c.action == "track" else None)
             for c in plan.commands]  # fmt: skip
    assert kinds == [("arm", None), ("track", "velocity"), ("track", "rates"),
                     ("track", "velocity"), ("disarm", None)]  # fmt: skip
    assert plan.commands[2].at_s + plan.start_s == pytest.approx(CLIMB_WINDOW_S[0])
    rates = plan.tracks["rates"]
    assert rates.values[1][3] == pytest.approx(0.0, abs=0.2)  # thrust = −thrust_body[2] ≥ 0


def test_a_late_start_arms_once_the_autopilot_is_ready(x500_path):
    plan = plan_replay(x500_path, ReplayOptions(start_s=408.5, end_s=412.0))
    assert plan.arm_s == pytest.approx(409.5)  # start + AUTOPILOT_READY_S, not 408.889
    assert "armed at 409.500 s instead of 408.889 s" in " ".join(t for _, t in plan.notes)


def test_vehicle_option_wins_and_keeps_the_log_cell_count(x500_path, tmp_path):
    plan = plan_replay(x500_path, ReplayOptions(vehicle="f450_high_precision"))
    assert plan.vehicle_reason == "--vehicle"
    assert plan.vehicle_document["battery"]["cell_count"] == 4


# -- bad input: one line naming the file, field and value ----------------------------------


def _synthetic_log(path: Path, parameters: dict, *, landed: bool = True,
                   setpoints: bool = True, battery_v: float | None = None) -> Path:  # fmt: skip
    """A small ULog with what a replay reads, 100-110 s, at rest."""
    topics = {
        "vehicle_status": [("uint64_t", "armed_time"), ("uint8_t", "arming_state")],
        "vehicle_land_detected": [("bool", "landed")],
        "vehicle_local_position": [("float", "heading")],
        "vehicle_local_position_setpoint": [
            ("float", "vx"),
            ("float", "vy"),
            ("float", "vz"),
            ("float", "yaw"),
        ],
    }
    if battery_v is not None:
        topics["battery_status"] = [("float", "voltage_v")]
    with ULogWriter(path, topics, info={"sys_name": "PX4"}, parameters=parameters) as log:
        for k in range(11):
            t_us = 100_000_000 + k * 1_000_000
            log.write("vehicle_status", t_us, armed_time=101_000_000, arming_state=2)
            log.write("vehicle_land_detected", t_us, landed=landed)
            log.write("vehicle_local_position", t_us, heading=0.5)
            if battery_v is not None:
                log.write("battery_status", t_us, voltage_v=battery_v)
            if setpoints:
                log.write("vehicle_local_position_setpoint", t_us, vx=0.0, vy=0.0, vz=0.0,
                          yaw=0.5)  # fmt: skip
    return path


def _error(path, **options) -> str:
    with pytest.raises((ReplayError, LogError)) as error:
        plan_replay(path, ReplayOptions(**options))
    message = str(error.value)
    assert "\n" not in message
    return message


def test_bad_logs_fail_with_one_line(tmp_path, x500_path):
    assert _error(tmp_path / "none.ulg") == f"{tmp_path / 'none.ulg'}: flight log not found"
    text = tmp_path / "text.ulg"
    text.write_text("not a flight log\n" * 20)
    assert _error(text).startswith(f"{text}: not a readable ULog file (")
    corrupt = tmp_path / "corrupt.ulg"
    corrupt.write_bytes(x500_path.read_bytes()[:16] + bytes(range(256)) * 50)
    assert _error(corrupt).startswith(f"{corrupt}: not a readable ULog file (")
    truncated = tmp_path / "truncated.ulg"
    truncated.write_bytes(x500_path.read_bytes()[:3000])
    assert _error(truncated) == f"{truncated}: the ULog holds no logged data"


def test_airframe_errors_name_the_parameter_and_the_override(tmp_path):
    no_autostart = _synthetic_log(tmp_path / "a.ulg", {"BAT1_N_CELLS": 4})
    assert _error(no_autostart) == (
        f"{no_autostart}: parameter SYS_AUTOSTART is not in the log; give --vehicle NAME|PATH"
    )
    unknown = _synthetic_log(tmp_path / "b.ulg", {"SYS_AUTOSTART": 4001})
    assert _error(unknown) == (
        f"{unknown}: parameter SYS_AUTOSTART = 4001 is an airframe without a bundled vehicle "
        "(known: 4019 x500_v2, 12001 auriol_x8); --vehicle NAME|PATH overrides it"
    )
    assert plan_replay(unknown, ReplayOptions(vehicle="x500_v2")).vehicle == "x500_v2"
    assert _error(unknown, vehicle="no_such_frame").startswith("--vehicle: ")


def test_out_of_range_parameters_are_reported_not_clamped(tmp_path):
    parameters = {"SYS_AUTOSTART": 4019, "MC_ROLLRATE_P": 0.9, "MC_PITCHRATE_P": 0.2,
                  "SDLOG_PROFILE": 1}  # fmt: skip
    log = _synthetic_log(tmp_path / "p.ulg", parameters)
    plan = plan_replay(log)
    assert plan.parameters == {"MC_PITCHRATE_P": pytest.approx(0.2)}
    (skipped,) = plan.skipped
    assert (skipped.name, skipped.value) == ("MC_ROLLRATE_P", pytest.approx(0.9))
    assert "outside 0.01..0.5" in skipped.reason
    assert plan.unknown_parameter_count == 2  # SYS_AUTOSTART, SDLOG_PROFILE
    assert ("warn", f"replay: parameter MC_ROLLRATE_P = 0.9 skipped ({skipped.reason})") in (
        plan.notes
    )


def test_bad_options_fail_with_one_line(tmp_path, x500_path):
    assert _error(x500_path, drive="rates") == (
        "--drive rates needs --window START END (boot seconds): it is open loop on position, "
        "the velocity drive flies outside it"
    )
    assert _error(x500_path, drive="attitude", window_s=(500.0, 510.0)) == (
        f"{x500_path}: --window 500 510 must lie inside the replay (408.404-504.068 s) with "
        "START < END"
    )
    assert _error(x500_path, end_s=600.0) == (
        f"{x500_path}: --end 600 s is outside the log (407.404-504.068 s)"
    )
    assert _error(x500_path, imu_hz=333) == (
        f"{x500_path}: --imu-hz = 333: must give a whole number of µs per frame"
    )
    no_setpoints = _synthetic_log(tmp_path / "s.ulg", {"SYS_AUTOSTART": 4019}, setpoints=False)
    assert _error(no_setpoints) == (
        f"{no_setpoints}: topic vehicle_local_position_setpoint (needed by --drive velocity) "
        "is not in the log"
    )
    assert _error(no_setpoints, drive="rates", window_s=(103.0, 104.0)) == (
        f"{no_setpoints}: topic vehicle_local_position_setpoint (needed by --drive velocity) "
        "is not in the log"
    )
    airborne = _synthetic_log(tmp_path / "air.ulg", {"SYS_AUTOSTART": 4019}, landed=False)
    assert _error(airborne) == (
        f"{airborne}: topic vehicle_local_position has no field z (the height at an airborne start)"
    )


def test_an_airborne_start_takes_off_to_the_logs_height_first(x500_path):
    """No autopilot boots flying (PX4 SITL neither): a log airborne at --start is flown after
    a lead-in (arm, take off to its height, settle), then its setpoints on its own clock."""
    plan = plan_replay(x500_path, ReplayOptions(start_s=430.0, end_s=445.0))
    assert plan.start_height_m == pytest.approx(4.98, abs=0.01)  # vehicle_local_position.z
    assert plan.lead_in_s == pytest.approx(1.0 + plan.start_height_m / 1.5 + 5.0)
    arm, takeoff, track = plan.commands
    assert (type(arm).__name__, arm.at_s) == ("Arm", 1.0)
    assert (takeoff.at_s, takeoff.altitude_m) == (1.1, plan.start_height_m)
    assert track.at_s == plan.lead_in_s == track.track.times_s[0]
    scenario = plan.scenario(Path("x500_v2"))
    assert scenario.start.clock_s + plan.lead_in_s == 430.0  # the track starts at the log's 430 s
    assert scenario.duration_s == pytest.approx(15.0 + plan.lead_in_s)
    assert any("starts airborne at 430.000 s" in text for _, text in plan.notes)


def test_cli_prints_one_line_errors(capsys, tmp_path):
    assert main(["replay", str(tmp_path / "missing.ulg")]) == 1
    assert (
        capsys.readouterr().err == f"rig: error: {tmp_path / 'missing.ulg'}: flight log not found\n"
    )


# -- flights ----------------------------------------------------------------------------------


def test_replay_runs_on_the_real_logs_clock_and_takes_off_with_it(takeoff, real_log):
    out, rig, autopilot = takeoff
    for log in (rig, autopilot):
        times_s = np.concatenate([d.data["timestamp"] for d in log.data_list]) / 1e6
        assert times_s.min() >= X500_FIRST_S
        assert times_s.max() <= 420.0
    summary = json.loads((out / "replay.json").read_text())
    assert summary["parameters_applied"]["MC_ROLLRATE_P"] == pytest.approx(0.14)
    assert summary["wind"]["speed_mps"] == pytest.approx(4.8, abs=0.3)  # rig.identify.wind
    assert "cell_count = 4" in (out / "vehicle.toml").read_text()
    # lift-off: the first climb faster than 0.3 m/s (the real z estimate drifts by 0.1 m on
    # the ground, its vz does not)
    truth = rig.get_dataset("vehicle_local_position_groundtruth").data
    truth_s = truth["timestamp"] / 1e6
    sim_liftoff_s = truth_s[np.argmax(truth["vz"] < -0.3)]
    real = real_log.get_dataset("vehicle_local_position").data
    real_liftoff_s = real["timestamp"][np.argmax(real["vz"] < -0.3)] / 1e6
    assert real_liftoff_s == pytest.approx(413.0, abs=0.5)  # README: the climb from 413
    assert sim_liftoff_s == pytest.approx(real_liftoff_s, abs=1.0)
    # the climb tracks the real vz_sp step (−1.5 m/s from 413.5 to 417.2 s; the log's vz_sp
    # already holds PX4's smooth-takeoff ramp). The autopilot assumes MPC_THR_HOVER = 0.5
    # (PX4 estimates it in flight, the reference autopilot does not) while the model hovers
    # a little below it, so the velocity integrator needs a few seconds to take the surplus
    # out: the climb first overshoots, then settles on the setpoint.
    climb = (truth_s > 413.8) & (truth_s < 417.2)
    assert float(truth["vz"][climb].min()) > -1.5 - 0.8
    assert float(truth["vz"][climb].mean()) == pytest.approx(-1.5, abs=0.6)
    # and it follows the step back down to the real −0.3 m/s hold (418.4-419.0 s)
    leveled = (truth_s > 418.4) & (truth_s < 419.0)
    assert float(truth["vz"][leveled].mean()) == pytest.approx(-0.3, abs=0.2)
    events = [m.message for m in autopilot.logged_messages]
    assert events[:2] == ["Armed by external command", "Takeoff detected"]


def test_armed_motors_idle_and_the_hover_thrust_matches_the_real_one(takeoff, real_log):
    out, rig, autopilot = takeoff
    summary = json.loads((out / "replay.json").read_text())
    assert summary["motor_pwm_range_us"] == [1100.0, 1900.0]
    assert summary["initial_battery_voltage_v"] == pytest.approx(15.2, abs=0.2)
    # armed at 408.9 s, lift-off ≈ 412.6 s: command 0 is 1100 µs, the props spin at idle
    propulsion = rig.get_dataset("rig_propulsion_groundtruth").data
    t_s = propulsion["timestamp"] / 1e6
    armed_idle = (t_s > X500_ARMED_S + 0.5) & (t_s < 412.0)
    for rotor in range(4):
        assert propulsion[f"rotor_speed_radps[{rotor}]"][armed_idle].min() > 100.0

    # the hover after the climb (419-420 s): thrust setpoint vs the real log's ≈ 0.52
    def mean_thrust(log: pyulog.ULog) -> float:
        data = log.get_dataset("vehicle_thrust_setpoint").data
        times_s = data["timestamp"] / 1e6
        return float(-data["xyz[2]"][(times_s > 419.0) & (times_s < 420.0)].mean())

    real = mean_thrust(real_log)
    assert real == pytest.approx(0.52, abs=0.02)
    assert mean_thrust(autopilot) == pytest.approx(real, abs=0.06)


def test_autopilot_logs_topics_at_least_at_the_real_rates(takeoff):
    _, _, autopilot = takeoff
    # data/flight_logs/README.md rates of the real X500 log (Hz)
    real_hz = {"vehicle_rates_setpoint": 49.8, "vehicle_attitude_setpoint": 19.9,
               "vehicle_local_position_setpoint": 10, "vehicle_torque_setpoint": 49.8,
               "vehicle_thrust_setpoint": 49.8, "actuator_motors": 10,
               "sensor_combined": 200.8}  # fmt: skip
    for topic, hz in real_hz.items():
        t = autopilot.get_dataset(topic).data["timestamp"] / 1e6
        assert (len(t) - 1) / (t[-1] - t[0]) >= hz * 0.99, topic
    combined = autopilot.get_dataset("sensor_combined").data
    assert set(combined["gyro_integral_dt"]) == {5000}  # 1 kHz samples in 200 Hz blocks
    assert set(combined["accelerometer_integral_dt"]) == {5000}


def test_same_seed_same_replay(takeoff, x500_path, tmp_path, free_instance):
    _, first_rig, first_autopilot = takeoff
    rig, autopilot = _fly(x500_path, tmp_path, free_instance(), end_s=420.0)
    for name, a, b in (("sensor_combined", first_rig, rig),
                       ("actuator_motors", first_autopilot, autopilot)):  # fmt: skip
        x, y = a.get_dataset(name).data, b.get_dataset(name).data
        assert x.keys() == y.keys()
        for field in x:
            np.testing.assert_array_equal(x[field], y[field], err_msg=f"{name}.{field}")


@pytest.mark.parametrize(
    ("drive", "topic", "fields"),
    [
        ("rates", "vehicle_rates_setpoint", ("roll", "pitch", "yaw", "thrust_body[2]")),
        ("attitude", "vehicle_attitude_setpoint",
         ("q_d[0]", "q_d[1]", "q_d[2]", "q_d[3]", "thrust_body[2]")),
    ],
)  # fmt: skip
def test_window_drive_flies_the_logs_setpoints(
    drive, topic, fields, x500_path, real_log, tmp_path, free_instance
):
    """Inside the window the autopilot's logged setpoints are the real log's, sample for
    sample (zero-order hold): each real sample is in force from the first frame after it
    (1 ms) and the fast log's 4 ms period, so every rig sample from 5 ms after it to the next
    real sample equals it (float32; the attitude is renormalized, hence 1e-6). The window
    holds the estimator's heading reset at 415.14 s: an attitude set-point before it is the
    log's turned about down by the reset, into the frame the replay starts in."""
    _, autopilot = _fly(x500_path, tmp_path, free_instance(), drive=drive, end_s=417.0,
                        window_s=CLIMB_WINDOW_S)  # fmt: skip
    ((reset_s, delta),) = plan_replay(x500_path).heading_resets
    turn = np.array([math.cos(delta / 2), 0.0, 0.0, math.sin(delta / 2)])
    real = real_log.get_dataset(topic).data
    rig = autopilot.get_dataset(topic).data
    real_s, rig_s = real["timestamp"] / 1e6, rig["timestamp"] / 1e6
    inside = np.nonzero((real_s >= CLIMB_WINDOW_S[0]) & (real_s < CLIMB_WINDOW_S[1]))[0]
    compared = 0
    for k in inside[:-1]:
        held = (rig_s >= real_s[k] + 0.005) & (rig_s < real_s[k + 1])
        expected = [real[field][k] for field in fields]
        if drive == "attitude" and real_s[k] < reset_s:
            expected[:4] = quat_multiply(turn, np.array(expected[:4]))
        for field, value in zip(fields, expected, strict=True):
            np.testing.assert_allclose(rig[field][held], value, rtol=0, atol=1e-6)
        compared += int(held.sum())
    assert len(inside) >= 19
    assert compared >= len(inside)
    after = rig_s > CLIMB_WINDOW_S[1] + 0.1  # the velocity drive is back: its own setpoints
    assert not np.isin(rig[fields[0]][after], real[fields[0]]).all()


@pytest.mark.closed_loop
def test_an_airborne_start_is_in_the_air_at_the_logs_start(x500_path, real_log, tmp_path,
                                                           free_instance):  # fmt: skip
    """Replayed from 430 s, where the real X500 hovers at 5 m: after the lead-in the rig
    is at that height when its clock reaches 430 s, and then flies the log's setpoints (the
    real descent of 431-436 s; how closely is the credibility study's question)."""
    rig, _ = _fly(x500_path, tmp_path / "air", free_instance(), start_s=430.0, end_s=438.0)
    truth = rig.get_dataset("vehicle_local_position_groundtruth").data
    real = real_log.get_dataset("vehicle_local_position").data

    def height(data, time_s):
        return float(-np.interp(time_s * 1e6, data["timestamp"], data["z"]))

    assert height(truth, 430.0) == pytest.approx(height(real, 430.0), abs=0.5)
    descent = (truth["timestamp"] >= 431e6) & (truth["timestamp"] <= 436e6)
    real_descent = (real["timestamp"] >= 431e6) & (real["timestamp"] <= 436e6)
    assert real["vz"][real_descent].mean() > 0.1  # NED: down
    assert truth["vz"][descent].mean() > 0.1
    messages = [m.message for m in rig.logged_messages]
    assert any("starts airborne at 430.000 s" in text for text in messages)
    assert any(text.startswith("takeoff to 4.98") for text in messages)


def test_the_three_real_logs_are_planned_or_refused_naming_what_is_missing(
    x500_path, quad4001_log, auriol_log
):
    """The X500 flight and the 8S quad's hover (an airframe we have no file for, flown as the
    X500 with --vehicle) plan and identify; the X8's ground run never flew and logged no
    arming state, so the replay says what its start would need, and identify refuses its
    eight rotors before anything else."""
    x500 = load_vehicle("x500_v2")
    for log in (x500_path, quad4001_log):
        assert plan_replay(log, ReplayOptions(vehicle="x500_v2")).arm_s is not None
        assert 0.2 < identify_vehicle(FlightLog.read(log), x500).hover.throttle.value < 0.7
    no_start = r"no vehicle_land_detected, and no arming state \(actuator_armed, vehicle_status\)"
    with pytest.raises(LogError, match=no_start):
        plan_replay(auriol_log, ReplayOptions(vehicle="x500_v2"))
    eight_rotors = r": 8 rotors .* the identification handles 4$"
    with pytest.raises(IdentificationError, match=eight_rotors):
        identify_vehicle(FlightLog.read(auriol_log), x500)


def test_the_8s_quads_replay_starts_at_its_logs_header(quad4001_log):
    """Its topics hold samples published long before logging began (actuator_outputs at
    0.6 s, the logger started at 104.889 s, on arming): the replay starts at the header's
    start time and arms as soon as the reference autopilot can, with the log's 8 cells."""
    plan = plan_replay(
        quad4001_log,
        ReplayOptions(vehicle="quad4001_8s", drive="attitude", window_s=(109.0, 195.5)),
    )
    assert plan.start_s == pytest.approx(104.889396, abs=1e-6)
    assert plan.arm_s == pytest.approx(plan.start_s + 1.0)
    assert plan.cell_count == 8
    assert plan.initial_battery_voltage_v == pytest.approx(30.9, abs=0.1)
    assert plan.learned == {}  # PX4's hover estimate matters to PX4 only
