"""Vehicle files: the bundled sets load and make sense; bad files fail with one clear line."""

import tomllib

import pytest

from quad_model import VehicleFileError, load_vehicle
from quad_model.vehicle import VEHICLES_DIR


@pytest.mark.parametrize(
    ("name", "hover_radps", "mass_kg"),
    [
        # √(m·g/(4·C_T)) from each file's mass and thrust coefficient.
        ("f450_high_precision", 557.33, 1.4),
        ("f450_low_precision", 555.08, 1.4),
        ("x500_v2", 576.37, 2.0),
    ],
)
def test_bundled_vehicles_load(name, hover_radps, mass_kg):
    vehicle = load_vehicle(name)
    assert vehicle.body.mass_kg == mass_kg
    assert vehicle.hover_rotor_speed_radps == pytest.approx(hover_radps, abs=0.01)
    # PX4 quad X: 0 front-right CCW, 1 rear-left CCW, 2 front-left CW, 3 rear-right CW.
    signs = [(x > 0, y > 0) for x, y, _ in vehicle.propulsion.position_frd_m]
    assert signs == [(True, True), (False, False), (True, False), (False, True)]
    assert vehicle.propulsion.spin_direction == (1.0, 1.0, -1.0, -1.0)


def test_f450_high_precision_hover_throttle_matches_rflysim():
    # RflySim's F450: hover throttle 0.609 with ω = C_R·σ + ω_b at the curve voltage.
    prop = load_vehicle("f450_high_precision").propulsion
    hover = load_vehicle("f450_high_precision").hover_rotor_speed_radps
    throttle = (hover - prop.speed_offset_radps) / prop.speed_slope_radps
    assert throttle == pytest.approx(0.609, abs=0.002)


def _write(tmp_path, text):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    return path


#: Vibration operating points appended to the F450's [vibration] table (before [baro]).
_LEVELS = (
    "level_rotor_speed_radps = {speeds}\naccel_tone_level = {tone}\n"
    "accel_broadband_level = [[1, 1, 1], [1, 1, 1]]\ngyro_tone_level = [[1, 1, 1], [1, 1, 1]]\n"
    "gyro_broadband_level = [[1, 1, 1], [1, 1, 1]]\n\n[baro]\n"
)


def _edited(tmp_path, old, new):
    text = (VEHICLES_DIR / "f450_high_precision.toml").read_text(encoding="utf-8")
    assert old in text
    return _write(tmp_path, text.replace(old, new, 1))


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("mass_kg = 1.4 ", "", "key 'body.mass_kg' is missing"),
        ("mass_kg = 1.4 ", "mass_kg = -1.4 ", "key 'body.mass_kg' = -1.4: expected a value > 0"),
        (
            "mass_kg = 1.4 ",
            'mass_kg = "heavy" ',
            "key 'body.mass_kg' = 'heavy': expected a valid number",
        ),
        (
            "mass_kg = 1.4 ",
            "mass_kg = 1.4\nmass_lb = 3.1 ",
            "key 'body.mass_lb' = 3.1: unknown key",
        ),
        (
            "blade_count = 2",
            "blade_count = 2.5",
            "key 'propulsion.blade_count' = 2.5: expected a valid integer",
        ),
        (
            "drag_area_m2 = [0.0898, 0.0898, 0.0898]",
            "drag_area_m2 = [0.0898, 0.0898]",
            "key 'body.drag_area_m2[2]' is missing",
        ),
        (
            "min_throttle = 0.05",
            "min_throttle = 1.5",
            "key 'propulsion.min_throttle' = 1.5: expected a value <= 1",
        ),
        (
            "spin_direction = [1, 1, -1, -1]",
            "spin_direction = [1, 1, -1, 0]",
            "key 'propulsion.spin_direction' = [1.0, 1.0, -1.0, 0.0]: "
            "must hold +1 (CCW) or -1 (CW)",
        ),
        (
            "[0.0, 0.0, 0.0366]",
            "[0.0, 0.0, -0.0366]",
            "key 'body.inertia_kgm2' = [[0.0211, 0.0, 0.0], [0.0, 0.0219, 0.0], "
            "[0.0, 0.0, -0.0366]]: must be symmetric positive definite",
        ),
        ("[gps]\n", "[gnss]\n", "key 'gps' is missing"),
        (
            "[baro]\n",
            _LEVELS.format(speeds="[600.0, 500.0]", tone="[[1, 1, 1], [1, 1, 1]]"),
            "key 'vibration.level_rotor_speed_radps' = [600.0, 500.0]: must be strictly ascending",
        ),
        (
            "[baro]\n",
            _LEVELS.format(speeds="[500.0, 600.0]", tone="[[1, 1, 1]]"),
            "key 'vibration.accel_tone_level' = [[1.0, 1.0, 1.0]]: needs one [x, y, z] per "
            "rotor speed (2)",
        ),
    ],
)
def test_bad_vehicle_file_names_the_key(tmp_path, old, new, message):
    path = _edited(tmp_path, old, new)
    with pytest.raises(VehicleFileError) as caught:
        load_vehicle(path)
    assert str(caught.value) == f"{path}: {message}"
    assert "\n" not in str(caught.value)


def test_missing_table_and_unreadable_files(tmp_path):
    text = (VEHICLES_DIR / "f450_high_precision.toml").read_text(encoding="utf-8")
    path = _write(tmp_path, text.split("[mag]")[0])
    with pytest.raises(VehicleFileError, match=r"bad.toml: key 'mag' is missing$"):
        load_vehicle(path)
    path = _write(tmp_path, "name = 'x'\n[body\n")
    with pytest.raises(VehicleFileError, match=r"bad.toml: not valid TOML \("):
        load_vehicle(path)
    with pytest.raises(VehicleFileError, match=r"no_such.toml: no such vehicle file \(bundled: "):
        load_vehicle(tmp_path / "no_such.toml")
    with pytest.raises(VehicleFileError, match=r"bundled: auriol_x8, f450_high_precision, f450_lo"):
        load_vehicle("f550")


def test_every_bundled_value_has_a_provenance_comment():
    for path in VEHICLES_DIR.glob("*.toml"):
        tomllib.loads(path.read_text(encoding="utf-8"))
        lines = path.read_text(encoding="utf-8").splitlines()
        for number, line in enumerate(lines):
            is_value = (
                "=" in line and not line.lstrip().startswith("#") and not line.startswith("name")
            )
            if is_value and line.rstrip().endswith(("[", "]")) is False:
                commented = "#" in line or lines[number - 1].lstrip().startswith("#")
                assert commented, f"{path.name}:{number + 1} has no provenance comment: {line}"
