"""Rangefinder physics: closed-form ranges level and tilted, the range and tilt limits,
noise level, determinism, and the suite's schedule."""

import math
from dataclasses import asdict

import numpy as np
import pytest

from quad_model import SensorSuite, load_vehicle
from quad_model import dynamics as dyn
from quad_model.environment import Environment
from quad_model.frames import quat_from_euler
from quad_model.model import VehicleTruth
from quad_model.sensors import RangefinderModel, SensorConfigError
from quad_model.vehicle import VehicleFileError, vehicle_from_dict


def truth_at(down_m: float, roll_deg: float = 0.0, pitch_deg: float = 0.0, t_us: int = 0):
    state = np.zeros(dyn.X_SIZE)
    state[dyn.X_TIME_US] = t_us
    state[dyn.X_POS + 2] = down_m
    state[dyn.X_QUAT : dyn.X_QUAT + 4] = quat_from_euler(
        math.radians(roll_deg), math.radians(pitch_deg), 0.3
    )
    return VehicleTruth(state, np.zeros(dyn.A_SIZE), rotors=4)


@pytest.fixture
def quiet(f450, variant):
    """The F450's LIDAR-Lite without noise: every range is the closed form."""
    return variant(f450, rangefinder={"noise_std_m": 0.0}).rangefinder


def test_level_range_is_height_of_the_sensor(quiet):
    model = RangefinderModel(quiet, np.random.default_rng(1))
    # The sensor sits 0.10 m above the reference point: 5 m up reads 5.10 m.
    assert model.sample(truth_at(-5.0)).distance_m == pytest.approx(5.10, abs=1e-12)
    assert model.sample(truth_at(0.0)).distance_m == pytest.approx(0.10, abs=1e-12)


@pytest.mark.parametrize(("roll_deg", "pitch_deg"), [(30.0, 0.0), (0.0, -20.0), (25.0, 25.0)])
def test_tilt_lengthens_the_range_by_one_over_cos(quiet, roll_deg, pitch_deg):
    model = RangefinderModel(quiet, np.random.default_rng(1))
    roll, pitch = math.radians(roll_deg), math.radians(pitch_deg)
    cos_tilt = math.cos(roll) * math.cos(pitch)  # body z in NED down, yaw-free
    # The mount point 0.10 m up the body z axis is 0.10·cos_tilt above the reference point.
    expected = (8.0 + 0.10 * cos_tilt) / cos_tilt
    sample = model.sample(truth_at(-8.0, roll_deg, pitch_deg))
    assert sample.distance_m == pytest.approx(expected, abs=1e-12)


def test_no_return_beyond_max_range_or_past_the_tilt_limit(quiet):
    model = RangefinderModel(quiet, np.random.default_rng(1))
    assert model.sample(truth_at(-39.89)).distance_m == pytest.approx(39.99, abs=1e-9)
    assert model.sample(truth_at(-39.91)).distance_m is None  # 40.01 m
    # 10 m up at 44° reads 10.1/cos 44° = 14.04 m; at 46° the beam is past 45°.
    assert model.sample(truth_at(-10.0, roll_deg=44.0)).distance_m == pytest.approx(
        (10.0 + 0.10 * math.cos(math.radians(44))) / math.cos(math.radians(44)), abs=1e-12
    )
    assert model.sample(truth_at(-10.0, roll_deg=46.0)).distance_m is None
    # Within the tilt limit but the slant range is past 40 m: 30 m at 45° is 42.5 m.
    assert model.sample(truth_at(-30.0, roll_deg=44.9)).distance_m is None


def test_noise_sigma_and_the_same_seed_gives_the_same_numbers(f450):
    params = f450.rangefinder
    samples = [
        RangefinderModel(params, np.random.default_rng(7)).sample(truth_at(-3.0)).distance_m
        for _ in range(2)
    ]
    assert samples[0] == samples[1]
    model = RangefinderModel(params, np.random.default_rng(7))
    values = np.array([model.sample(truth_at(-3.0)).distance_m for _ in range(4000)])
    # σ of 4000 normal draws is within ±5 % of the true σ at about 3.5 sigma.
    assert values.std() == pytest.approx(params.noise_std_m, rel=0.05)
    assert values.mean() == pytest.approx(3.10, abs=4 * params.noise_std_m / math.sqrt(4000))


def test_a_no_return_still_draws_so_later_numbers_do_not_shift(f450):
    params = f450.rangefinder
    a, b = (RangefinderModel(params, np.random.default_rng(3)) for _ in range(2))
    a.sample(truth_at(-50.0))  # out of range: no return
    b.sample(truth_at(-2.0))
    assert a.sample(truth_at(-2.0)).distance_m == b.sample(truth_at(-2.0)).distance_m


def test_suite_samples_at_its_rate_and_keeps_the_other_sensors_numbers(f450):
    env = Environment()
    plain = SensorSuite(f450, env, np.random.default_rng(5))
    ranged = SensorSuite(f450, env, np.random.default_rng(5), rangefinder_rate_hz=20.0)
    due = []
    for t_us in range(0, 200_000, 1000):
        truth = truth_at(-2.0, t_us=t_us)
        a, b = plain.sample(truth), ranged.sample(truth)
        assert a.range is None
        np.testing.assert_array_equal(a.imu.accel_mps2, b.imu.accel_mps2)
        if b.range is not None:
            due.append(t_us)
    assert due == [0, 50_000, 100_000, 150_000]


def test_a_vehicle_without_one_cannot_sample_range(f450, variant):
    bare = load_vehicle("f450_low_precision")
    assert bare.rangefinder is None
    with pytest.raises(SensorConfigError, match=r"has no \[rangefinder\] table$"):
        SensorSuite(bare, Environment(), np.random.default_rng(1), rangefinder_rate_hz=20.0)


def test_bad_rangefinder_keys_name_the_key(f450):
    document = {
        "position_frd_m": [0, 0, 0],
        "axis_frd": [0, 0, 0],
        "max_range_m": 40.0,
        "noise_std_m": 0.02,
        "max_tilt_deg": 45.0,
    }
    base = {k: v for k, v in asdict(f450).items() if k != "rangefinder"}
    with pytest.raises(VehicleFileError, match=r"axis_frd.*must be a direction"):
        vehicle_from_dict(base | {"rangefinder": document}, "v.toml")
    with pytest.raises(VehicleFileError, match=r"max_tilt_deg"):
        vehicle_from_dict(
            base | {"rangefinder": document | {"axis_frd": [0, 0, 1], "max_tilt_deg": 90}}, "v.toml"
        )
