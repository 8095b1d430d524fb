"""``rig vehicle LOG --mass KG``: a vehicle file from a log. On the real X500 and 8S logs the
values both the file and the bundled vehicle take from the log agree within the file's stated
±; a rig flight of a known vehicle gives back its hover and k_T; every value is tagged; the
file loads and flies; a log the model cannot fly, or bad input, is one line."""

import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from px4_logs import FlightLog
from quad_model.frames import STANDARD_GRAVITY_MPS2
from quad_model.vehicle import load_vehicle
from rig import cli
from rig.identify import IdentificationError
from rig.identify.generic import (
    FULL_THROTTLE_THRUST_TO_WEIGHT,
    HOVER_THROTTLE,
    frame_class,
    generic_vehicle,
)
from rig.identify.vehicle_file import TAGS, vehicle_from_log
from tests.rig.flights import fly
from tests.rig.test_identify import (
    FAST_TOPICS,
    FLIGHT_LOGS,
    _hover_throttle_at,
    _px4_style_log,
    _truth_vehicle_file,
)

X500_LOG = FLIGHT_LOGS / "px4_x500v2_v6xrt_flight_2026-03-20.ulg"
QUAD4001_LOG = FLIGHT_LOGS / "px4_quad4001_v6c_stab_hover_2026-03-09.ulg"
#: The values both a written file and the bundled one take from the log (the rest of the
#: bundled files is their own reading of the airframe, which the log cannot check).
FROM_THE_LOG = {
    "x500_v2": (
        "propulsion.thrust_coefficient_n_per_radps2",
        "propulsion.speed_offset_radps",
        "battery.internal_resistance_ohm",
        "imu.gyro_noise_density_radps_per_sqrthz",
        "imu.accel_noise_density_mps2_per_sqrthz",
    ),
    # k_T: the 8S log shows no rotor line, both files take a 15-inch C_T 0.1 prop (the
    # file's [default] ±); the speed offset follows each file's own full-throttle point,
    # so the hover is compared by the throttle it flies at instead (below)
    "quad4001_8s": (
        "propulsion.thrust_coefficient_n_per_radps2",
        "battery.internal_resistance_ohm",
        "imu.gyro_noise_density_radps_per_sqrthz",
        "imu.accel_noise_density_mps2_per_sqrthz",
    ),
}


def _write(log: Path, mass_kg: float, out: Path) -> tuple[str, dict]:
    result = vehicle_from_log(FlightLog.read(log), mass_kg, f"rig vehicle {log.name}")
    text = result.toml()
    out.write_text(text, encoding="utf-8")
    return text, tomllib.loads(text)


@pytest.fixture(scope="module")
def x500_file(tmp_path_factory):
    return _write(X500_LOG, 2.0, tmp_path_factory.mktemp("vehicle") / "x500.toml")


@pytest.fixture(scope="module")
def quad4001_file(tmp_path_factory):
    return _write(QUAD4001_LOG, 4.16, tmp_path_factory.mktemp("vehicle") / "quad4001.toml")


def _lines(text: str) -> dict[str, str]:
    """``table.key`` → the comment on its line."""
    table, comments = "", {}
    for line in text.splitlines():
        if header := re.fullmatch(r"\[(\w+)\]", line):
            table = header[1] + "."
        elif key := re.match(r"(\w+) = .*?   # (.*)$", line):
            comments[table + key[1]] = key[2]
    return comments


def _stated(comment: str, value: float) -> float:
    """The ± a line states (the first one: absolute, or a percentage of ``value``)."""
    found = re.search(r"± ([0-9.e-]+)( ?%)?", comment)
    assert found, comment
    return abs(value) * float(found[1]) / 100 if found[2] else float(found[1])


def _value(document: dict, key: str) -> float:
    table, name = key.split(".")
    return document[table][name]


@pytest.mark.parametrize(
    ("bundled", "file_fixture"), [("x500_v2", "x500_file"), ("quad4001_8s", "quad4001_file")]
)
def test_the_file_holds_what_the_log_says_within_its_stated_uncertainty(
    bundled, file_fixture, request
):
    """Known-answer data: the bundled files' log-derived values (X500: k_T from the rotor
    line, the hover's speed offset, R, the IMU noise at rest; 8S: R, the noise) within the
    written file's ± on the line. Measured (bundled − written): X500 k_T 0.0 %, offset +4
    rad/s of ± 52, R 0.0 %, noise 0.0 %; 8S k_T -8 % of ± 30 %, R -0.9 % of ± 1.2 %, noise
    0.0 %."""
    text, document = request.getfixturevalue(file_fixture)
    reference = load_vehicle(bundled)
    comments = _lines(text)
    for key in FROM_THE_LOG[bundled]:
        table, name = key.split(".")
        ours = _value(document, key)
        expected = getattr(getattr(reference, table), name)
        assert abs(ours - expected) <= _stated(comments[key], ours), (key, ours, expected)


@pytest.mark.parametrize(
    ("log", "file_fixture"), [(X500_LOG, "x500_file"), (QUAD4001_LOG, "quad4001_file")]
)
def test_the_file_flies_the_logs_hover_throttle(log, file_fixture, request, tmp_path):
    """The written speed curve puts the model's hover, on the thrust stand at the log's hover
    voltage and air density, at the log's hover throttle within the file's stated ± (X500
    0.522 ± 0.017, 8S 0.623 ± 0.018)."""
    text, _ = request.getfixturevalue(file_fixture)
    path = tmp_path / "written.toml"
    path.write_text(text, encoding="utf-8")
    vehicle = load_vehicle(path)
    comment = _lines(text)["propulsion.speed_offset_radps"]
    voltage = float(re.search(r"at ([0-9.]+) V", comment)[1])
    throttle, sigma = (float(v) for v in re.search(r"hover throttle ([0-9.]+) ± ([0-9.]+)",
                                                   comment).groups())  # fmt: skip
    log_data = FlightLog.read(log)
    t, rho = log_data.series("vehicle_air_data", "rho", "")
    windows = log_data.hover_windows()
    inside = np.any([(t >= a) & (t < b) for a, b in windows], axis=0)
    flown = _hover_throttle_at(vehicle, voltage, float(rho[inside].mean()))
    assert flown == pytest.approx(throttle, abs=sigma)


def test_every_value_is_tagged_and_the_file_loads(x500_file, tmp_path):
    """Each key's line carries one of the tags; what the log cannot give says so (the mass
    [given], the inertia ASSUMED); the file loads through the vehicle schema."""
    text, document = x500_file
    comments = _lines(text)
    keys = sum(len(table) for table in document.values() if isinstance(table, dict)) + 1
    assert len(comments) == keys
    for key, comment in comments.items():
        assert re.match(rf"\[({'|'.join(TAGS)})\] \S", comment), key
    assert comments["body.mass_kg"].startswith("[given]")
    assert "ASSUMED" in comments["body.inertia_kgm2"]
    assert "give --window START END" in comments["body.inertia_kgm2"]  # else unconfirmed
    assert comments["propulsion.spin_direction"].startswith("[log]")
    assert comments["battery.cell_count"] == "[log] BAT1_N_CELLS = 4"
    assert "`rig vehicle px4_x500v2_v6xrt_flight_2026-03-20.ulg`" in text.splitlines()[0]
    assert "PX4 v1.17.0rc" in text
    assert "SYS_AUTOSTART 4019" in text
    path = tmp_path / "x500.toml"
    path.write_text(text, encoding="utf-8")
    vehicle = load_vehicle(path)
    assert vehicle.body.mass_kg == 2.0
    # PX4's normalised square (±1) scaled to the frame class's arm, less the centre of mass
    hubs = np.array(vehicle.propulsion.position_frd_m)
    arm = np.hypot(*(hubs[:, :2] - hubs[:, :2].mean(axis=0)).T)
    np.testing.assert_allclose(arm, frame_class(2.0)[1], rtol=1e-5)


def test_the_8s_quads_esc_start_is_read_from_its_silent_armed_idle(quad4001_file):
    """The 8S quad armed at PWM 1100 µs (throttle 0.10) with its rotors stopped: the idle's
    accelerometer is quieter than after the disarm, so the ESCs start above it (0.12, as the
    bundled file reads it), and that idle is the IMU's rest."""
    text, document = quad4001_file
    assert document["propulsion"]["min_throttle"] == pytest.approx(0.12)
    comments = _lines(text)
    assert comments["propulsion.min_throttle"].startswith("[log]")
    assert "rest (105.1-109.6 s)" in comments["imu.gyro_noise_density_radps_per_sqrthz"]


@pytest.fixture(scope="module")
def climbing_flight(tmp_path_factory):
    """test_identify's known X500 variant flown up and down between 3 and 7 m, 32 s
    simulated: climbing, its rotors turn faster than in hover (axial inflow), descending
    slower, so the rotor line moves with the drive as on a real flight (a level zig-zag
    moves it too little to tell it from a folded one)."""
    folder = tmp_path_factory.mktemp("vehicle_from_log")
    truth_path = _truth_vehicle_file(folder)
    commands = [{"at_s": 0.5, "action": "arm"},
                {"at_s": 0.6, "action": "takeoff", "altitude_m": 3.0}]  # fmt: skip
    commands += [{"at_s": 8.0 + 6.0 * i, "action": "goto", "position_ned_m": [0, 0, -z]}
                 for i, z in enumerate((7.0, 3.0, 7.0, 3.0))]  # fmt: skip
    result = fly({"name": "climbs", "vehicle": str(truth_path), "duration_s": 32.0,
                  "seed": 7, "sensor_layer": "tlm", "commands": commands},
                 folder / "run")  # fmt: skip
    log = _px4_style_log(result.autopilot_log, result.rig_log, folder / "px4_style.ulg", 250.0,
                         (*FAST_TOPICS, "sensor_combined"), {"BAT1_N_CELLS": 4})  # fmt: skip
    return load_vehicle(truth_path), log


@pytest.mark.closed_loop
def test_a_known_vehicle_is_given_back_from_its_rig_flight(climbing_flight):
    """A rig flight of a known X500 variant, logged as PX4 would (with the IMU's
    sensor_combined at 250 Hz and the pack's cell count): the written file's k_T (the rotor
    line) and its hover (the throttle its speed curve hovers at, at the log's hover voltage)
    are the truth's within the file's stated ±, from a generic prior 13 % off in k_T."""
    truth, log = climbing_flight
    result = vehicle_from_log(FlightLog.read(log), truth.body.mass_kg, "rig vehicle")
    comments = _lines(result.toml())
    key = "propulsion.thrust_coefficient_n_per_radps2"
    assert comments[key].startswith("[identified]"), comments[key]
    k_t = result.vehicle.propulsion.thrust_coefficient_n_per_radps2
    expected = truth.propulsion.thrust_coefficient_n_per_radps2
    assert abs(k_t - expected) <= _stated(comments[key], k_t)
    comment = comments["propulsion.speed_offset_radps"]
    voltage = float(re.search(r"at ([0-9.]+) V", comment)[1])
    sigma = float(re.search(r"hover throttle [0-9.]+ ± ([0-9.]+)", comment)[1])
    assert _hover_throttle_at(result.vehicle, voltage) == pytest.approx(
        _hover_throttle_at(truth, voltage), abs=sigma
    )


@pytest.mark.closed_loop
def test_the_written_file_flies_a_hover(x500_file, tmp_path):
    """`rig run` with the written X500 file: take off to 3 m and hold; the true altitude
    stays within 0.5 m of 3 m over the last 3 s."""
    text, _ = x500_file
    path = tmp_path / "x500.toml"
    path.write_text(text, encoding="utf-8")
    commands = [{"at_s": 0.5, "action": "arm"},
                {"at_s": 0.6, "action": "takeoff", "altitude_m": 3.0}]  # fmt: skip
    result = fly({"name": "written_hover", "vehicle": str(path), "duration_s": 12.0,
                  "seed": 2, "sensor_layer": "tlm", "commands": commands},
                 tmp_path / "run")  # fmt: skip
    truth = FlightLog.read(result.rig_log)
    t, z = truth.series("vehicle_local_position_groundtruth", "z", "altitude")
    last = t >= t[-1] - 3.0
    np.testing.assert_allclose(-z[last], 3.0, atol=0.5)


def test_the_generic_multicopter_lands_near_the_bundled_ones():
    """Given the bundled X500's and F450's mass, cells and arm, the generic values lie within
    the factors the generic module states (measured, bundled ÷ generic, X500 / F450: k_T
    1.14 / 1.09, k_Q 0.65 / 1.15, inertia 1.0 / 1.7 (the F450's bench inertia), rotor inertia
    0.39 / 2.6, drag area 0.83 / 1.8, τ_m 1.0 / 1.13); and closed forms: the model's own hover
    on the thrust stand at the curve voltage in the reference air is at the generic hover
    throttle, full throttle gives twice the weight, k_T is C_T·ρD⁴/4π²."""
    factors = {
        ("propulsion", "thrust_coefficient_n_per_radps2"): 1.3,
        ("propulsion", "torque_coefficient_nm_per_radps2"): 1.6,
        ("body", "inertia_kgm2"): 2.0,
        ("propulsion", "rotor_inertia_kgm2"): 3.0,
        ("body", "drag_area_m2"): 2.0,
        ("propulsion", "motor_time_constant_s"): 2.0,
    }
    for name, cells, arm in (("x500_v2", 4, 0.246), ("f450_high_precision", 3, 0.225)):
        bundled = load_vehicle(name)
        generic = generic_vehicle(bundled.body.mass_kg, cells, arm).vehicle
        for (table, key), factor in factors.items():
            ours = np.array(getattr(getattr(generic, table), key), dtype=float)
            theirs = np.array(getattr(getattr(bundled, table), key), dtype=float)
            if ours.ndim == 2:
                ours, theirs = np.diag(ours), np.diag(theirs)
            ratio = theirs / ours
            assert np.all((1 / factor <= ratio) & (ratio <= factor)), (name, key, ratio)
    generic = generic_vehicle(2.0, 4).vehicle
    diameter, arm = frame_class(2.0)
    assert (diameter, arm) == pytest.approx((0.254, 0.246))  # the X500's class row
    prop = generic.propulsion
    assert prop.thrust_coefficient_n_per_radps2 == pytest.approx(
        0.10 * 1.225 * 0.254**4 / (4 * math.pi**2)
    )
    hover = _hover_throttle_at(
        generic, prop.speed_curve_voltage_v, prop.reference_air_density_kgpm3
    )
    assert hover == pytest.approx(HOVER_THROTTLE, abs=1e-3)
    full = prop.speed_slope_radps + prop.speed_offset_radps
    thrust = 4 * prop.thrust_coefficient_n_per_radps2 * full**2
    weight = generic.body.mass_kg * STANDARD_GRAVITY_MPS2
    assert thrust / weight == pytest.approx(FULL_THROTTLE_THRUST_TO_WEIGHT)


def test_a_log_of_another_rotor_count_is_one_line_and_no_file(auriol_log, tmp_path, capsys):
    out = tmp_path / "x8.toml"
    assert cli.main(["vehicle", str(auriol_log), "--mass", "30", "--out", str(out)]) == 1
    error = capsys.readouterr().err
    assert error.count("\n") == 1
    assert f"{auriol_log}: CA_ROTOR_COUNT = 8: the identification handles 4 rotors" in error
    assert not out.exists()


def test_bad_input_is_one_line(tmp_path, capsys):
    """No --mass, a negative or NaN mass, a log without the rotor count, a rotor's position,
    the cell count, or with PX4's default (all-zero) rotor geometry."""
    cases = [
        ([str(X500_LOG)], "--mass KG is required"),
        ([str(X500_LOG), "--mass", "-1"], "--mass -1: a mass is a positive number of kg"),
        ([str(X500_LOG), "--mass", "nan"], "--mass nan: a mass is a positive number of kg"),
        ([str(tmp_path / "missing.ulg"), "--mass", "2"], "flight log not found"),
    ]
    for args, message in cases:
        assert cli.main(["vehicle", *args]) == 1
        error = capsys.readouterr().err
        assert error.count("\n") == 1, error
        assert message in error
    log = FlightLog.read(X500_LOG)
    for removed, message in (
        ("CA_ROTOR_COUNT", "parameter CA_ROTOR_COUNT is not in the log"),
        ("CA_ROTOR2_PY", "parameter CA_ROTOR2_PY is not in the log"),
        ("BAT1_N_CELLS", "parameter BAT1_N_CELLS (BAT_N_CELLS in older PX4) is not set"),
        ("CA_ROTOR*_P", "CA_ROTORn_PX/PY place every rotor at the centre: no rotor geometry"),
    ):
        parameters = {k: v for k, v in log.parameters.items() if k != removed}
        if removed == "CA_ROTOR*_P":  # PX4's default geometry: every rotor at 0
            parameters |= {f"CA_ROTOR{i}_P{a}": 0.0 for i in range(4) for a in "XYZ"}
        stripped = FlightLog(log.path, log.topics, parameters)
        with pytest.raises(IdentificationError) as error:
            vehicle_from_log(stripped, 2.0, "rig vehicle")
        assert message in str(error.value)
        assert str(X500_LOG) in str(error.value)
        assert "\n" not in str(error.value)


def test_the_cli_writes_the_file_and_a_summary_per_table(tmp_path, capsys):
    out = tmp_path / "x500.toml"
    assert cli.main(["vehicle", str(QUAD4001_LOG), "--mass", "4.16", "--out", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith(f"{out}: PX4 airframe 4001")
    assert printed[1].strip() == "[body] 3 [default], 1 [given]"
    assert [line.split()[0] for line in printed[1:]] == [
        "[body]", "[propulsion]", "[battery]", "[imu]", "[vibration]", "[baro]", "[mag]", "[gps]"
    ]  # fmt: skip
    assert load_vehicle(out).battery.cell_count == 8
