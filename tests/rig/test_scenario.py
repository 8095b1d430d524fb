"""Scenario files: the bundled ones load; each kind of bad input fails with one exact line."""

import tomllib

import pytest

from quad_model.environment import PX4_DEFAULT_HOME
from rig.errors import ScenarioError
from rig.scenarios.scenario import SCENARIOS_DIR, Takeoff, load_scenario, scenario_from_dict

BUNDLED = sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))
MINIMAL = {"name": "t", "vehicle": "v", "duration_s": 2.0, "seed": 0}


@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_scenarios_load(name):
    scenario = load_scenario(name)
    assert scenario.name == name
    assert scenario.duration_s > 0
    times = [c.at_s for c in scenario.commands]
    assert times == sorted(times)


def test_required_bundle_is_shipped():
    assert {
        "takeoff_hover_land", "level_step", "pitch_sweep_bench", "motor_noise_bench", "hil_sim",
        "optical_flow_hold",
    } <= set(BUNDLED)  # fmt: skip


def test_defaults_are_px4_sitl_home_and_the_contract_rates():
    scenario = scenario_from_dict(MINIMAL)
    assert scenario.environment.home == PX4_DEFAULT_HOME
    assert (scenario.rates.model_hz, scenario.rates.imu_hz) == (5000, 1000)
    assert (scenario.rates.mag_hz, scenario.rates.baro_hz) == (50, 50)
    assert scenario.rates.pwm_hz == 400
    assert scenario.rates.frame_us == 1000
    assert scenario.sensor_layer == "tlm"
    assert scenario.constraint == "free"


@pytest.mark.parametrize(("imu_hz", "model_hz"), [(250, 5000), (400, 5200), (500, 5000)])
def test_model_rate_is_the_least_multiple_of_the_imu_rate_from_5khz(imu_hz, model_hz):
    """Every lockstep frame holds whole physics steps, at the paper's 5 kHz or just above."""
    scenario = scenario_from_dict({**MINIMAL, "rates": {"imu_hz": imu_hz}})
    assert scenario.rates.model_hz == model_hz


def test_full_document_is_converted():
    scenario = scenario_from_dict(
        MINIMAL
        | {
            "environment": {
                "home": {"lat_deg": 40.0, "lon_deg": 116.3, "alt_amsl_m": 50.0},
                "wind": {"steady_ned_mps": [1, 2, 0], "wind_at_6m_mps": 3.0},
            },
            "start": {"position_ned_m": [1, 2, 0], "yaw_deg": 90},
            "rates": {"imu_hz": 250},
            "commands": [
                {"at_s": 1.5, "action": "takeoff", "altitude_m": 3},
                {"at_s": 0.5, "action": "arm"},
            ],
            "faults": [
                {"kind": "motor_degradation", "motor": 2, "efficiency": 0.5, "start_s": 1,
                 "end_s": 1.5},
            ],
        }
    )  # fmt: skip
    assert scenario.environment.home.lat_deg == 40.0
    assert scenario.environment.wind.steady_ned_mps == (1.0, 2.0, 0.0)
    assert scenario.start.position_ned_m == (1.0, 2.0, 0.0)
    assert scenario.rates.frame_us == 4000
    assert [c.action for c in scenario.commands] == ["arm", "takeoff"]  # sorted by time
    assert scenario.commands[1] == Takeoff(at_s=1.5, altitude_m=3.0)
    fault = scenario.faults[0]
    assert fault.parameters == {"motor": 2, "efficiency": 0.5}
    assert (fault.active(0.99), fault.active(1.0), fault.active(1.49), fault.active(1.5)) == (
        False, True, True, False,
    )  # fmt: skip


BAD = [
    ({"duration_s": -1}, "key 'duration_s' = -1: expected a value > 0"),
    ({"duration_s": "10"}, "key 'duration_s' = '10': expected a valid number"),
    ({"seed": 1.5}, "key 'seed' = 1.5: expected a valid integer"),
    ({"sensor_layer": "fpga"}, "key 'sensor_layer' = 'fpga': expected 'tlm' or 'rtl'"),
    ({"speed": 3}, "key 'speed' = 3: unknown key"),
    ({"rates": {"imu_hz": 300}}, "key 'rates.imu_hz' = 300: must give a whole number of µs "
     "per frame"),
    ({"rates": {"imu_hz": 400, "model_hz": 5000}},
     "key 'rates.imu_hz' = 400: must divide model_hz (5000)"),
    ({"rates": {"mag_hz": 2000}}, "key 'rates.mag_hz' = 2000: exceeds imu_hz (1000)"),
    ({"start": {"position_ned_m": [0, 0, 1]}}, "key 'start.position_ned_m' = [0.0, 0.0, 1.0]: "
     "starts below the ground (down > 0)"),
    ({"environment": {"wind": {"steady_ned_mps": [1, 2]}}},
     "key 'environment.wind.steady_ned_mps[2]' is missing"),
    ({"environment": {"home": {"lat_deg": 95, "lon_deg": 0, "alt_amsl_m": 0}}},
     "key 'environment.home.lat_deg' = 95: expected a value <= 90"),
    ({"commands": [{"at_s": 1, "action": "flip"}]}, "key 'commands[0].action' = 'flip': "
     "expected one of 'arm', 'disarm', 'takeoff', 'land', 'hold', 'mode', 'sticks', 'goto', "
     "'mission', 'pitch_sweep', 'motor_test', 'set_param'"),
    ({"commands": [{"at_s": 1, "action": "mode", "name": "Posctl"}]},
     "key 'commands[0].name' = 'Posctl': not a PX4 mode to select (Manual, Altitude, Position, "
     "Mission, Hold, Return, Acro, Offboard, Stabilized, Takeoff, Land, Follow Me, "
     "Precision Land)"),
    ({"commands": [{"at_s": 1, "action": "sticks", "pitch": -1.5}]},
     "key 'commands[0].pitch' = -1.5: expected a value >= -1"),
    ({"optical_flow": 1}, "key 'optical_flow' = 1: expected a valid boolean"),
    ({"faults": [{"kind": "flow_chip", "mode": "stuck", "start_s": 1}]},
     "key 'faults[0].kind' = 'flow_chip': no optical-flow camera is flown"),
    ({"optical_flow": True, "faults": [{"kind": "flow_chip", "mode": "blind", "start_s": 1}]},
     "key 'faults[0].mode' = 'blind': expected 'stuck', 'zero_quality' or 'drop_frames'"),
    ({"commands": [{"at_s": 1}]}, "key 'commands[0].action' is missing"),
    ({"commands": [{"at_s": 1, "action": "takeoff"}]}, "key 'commands[0].altitude_m' is missing"),
    ({"commands": [{"at_s": 5, "action": "arm"}]},
     "key 'commands[0].at_s' = 5.0: not before the end of the run (duration_s = 2.0)"),
    ({"commands": [{"at_s": 1, "action": "arm", "altitude_m": 3}]},
     "key 'commands[0].altitude_m' = 3: unknown key"),
    ({"faults": [{"kind": "motor_loss", "motor": 8, "start_s": 1}]},
     "key 'faults[0].motor' = 8: expected a value <= 7"),
    ({"faults": [{"kind": "chip_mute", "chip": "bmi088", "start_s": 1}]},
     "key 'faults[0].chip' = 'bmi088': expected 'mpu6000', 'ms5611', 'ist8310', 'ublox', "
     "'lidarlite' or 'pmw3901'"),
    ({"faults": [{"kind": "gps_receiver", "fault": "spoofed", "start_s": 1}]},
     "key 'faults[0].fault' = 'spoofed': expected 'loss_of_fix', 'jammed' or 'bad_checksum'"),
    ({"faults": [{"kind": "gps_loss", "start_s": 1, "end_s": 0.5}]},
     "key 'faults[0].end_s' = 0.5: must be after start_s (1.0)"),
    ({"faults": [{"kind": "sensor_bias", "sensor": "gyro", "bias": 0.1, "start_s": 1}]},
     "key 'faults[0].bias' = 0.1: the gyro bias takes three numbers (sensor axes)"),
    ({"faults": [{"kind": "bus_bit_flip", "chip": "ms5611", "mask": 0, "start_s": 1}]},
     "key 'faults[0].mask' = 0: expected a value >= 1"),
]  # fmt: skip


@pytest.mark.parametrize(("change", "message"), BAD)
def test_bad_values_name_the_file_key_and_value(change, message):
    with pytest.raises(ScenarioError) as error:
        scenario_from_dict(MINIMAL | change, "s.toml")
    assert str(error.value) == f"s.toml: {message}"


def test_missing_required_key():
    with pytest.raises(ScenarioError, match=r"^s\.toml: key 'vehicle' is missing$"):
        scenario_from_dict({"name": "t", "duration_s": 1, "seed": 0}, "s.toml")


def test_unreadable_files(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text("name = \n")
    with pytest.raises(ScenarioError, match=r"broken\.toml: not valid TOML \(Invalid value"):
        load_scenario(broken)
    with pytest.raises(
        ScenarioError, match=r"nope\.toml: no such scenario file \(bundled: .*hil_sim"
    ):
        load_scenario(tmp_path / "nope.toml")


def test_bundled_files_are_plain_toml_without_unknown_sections():
    for path in SCENARIOS_DIR.glob("*.toml"):
        document = tomllib.loads(path.read_text())
        assert document["name"] == path.stem


def test_pwm_capture_tick_defaults_to_1_us_and_is_a_rates_setting():
    assert scenario_from_dict(MINIMAL).rates.pwm_tick_hz == 1_000_000
    rates = scenario_from_dict({**MINIMAL, "rates": {"pwm_tick_hz": 250_000}}).rates
    assert rates.pwm_tick_hz == 250_000


@pytest.mark.parametrize(
    ("rates", "reason"),
    [
        ({"pwm_tick_hz": 50_000}, "must be within 100000..2500000 Hz (10 µs to 0.4 µs ticks)"),
        ({"pwm_tick_hz": 5_000_000}, "must be within 100000..2500000 Hz (10 µs to 0.4 µs ticks)"),
        ({"pwm_tick_hz": 300_000}, "must divide 10000000 Hz (a whole number of 0.1 µs cycles)"),
        ({"pwm_tick_hz": 1e6}, "expected a valid integer"),
        (
            {"pwm_tick_hz": 250_000, "pwm_hz": 490},
            "the PWM period (2041 µs at pwm_hz = 490) is not a whole number of ticks (4 µs)",
        ),
    ],
)
def test_bad_pwm_capture_tick_is_one_line(rates, reason):
    value = rates["pwm_tick_hz"]
    message = f"<dict>: key 'rates.pwm_tick_hz' = {value!r}: {reason}"
    with pytest.raises(ScenarioError) as error:
        scenario_from_dict({**MINIMAL, "rates": rates})
    assert str(error.value) == message
