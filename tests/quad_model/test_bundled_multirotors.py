"""The bundled hexa (f550_hexa) and coaxial X8 (auriol_x8): their rotor tables are PX4's, their
hover is the closed form's, and the model holds them there with every moment balanced."""

import math

import numpy as np
import pytest

from quad_model import QuadModel, load_vehicle
from quad_model.environment import Environment, isa_density_kgpm3
from quad_model.frames import STANDARD_GRAVITY_MPS2
from quad_model.vehicle import AIRFRAMES, vehicle_for_airframe

G = STANDARD_GRAVITY_MPS2
HOVER_ALTITUDE_M = 10.0


def test_the_hexa_is_px4s_hexa_x_on_the_f550s_arms():
    """PX4's 6001 order and spins (0 right CW, 1 left CCW, 2 front-left CW, 3 rear-right CCW,
    4 front-right CCW, 5 rear-left CW) at 0.275 m, the F550's 550 mm diagonal."""
    prop = load_vehicle("f550_hexa").propulsion
    hubs = np.array(prop.position_frd_m)
    bearings = np.degrees(np.arctan2(hubs[:, 1], hubs[:, 0]))
    np.testing.assert_allclose(bearings, [90, -90, -30, 150, 30, -150], atol=0.05)
    np.testing.assert_allclose(np.hypot(hubs[:, 0], hubs[:, 1]), 0.275, atol=1e-4)
    assert prop.spin_direction == (-1, 1, -1, 1, 1, -1)
    assert prop.coaxial_lower == (False,) * 6


def test_the_x8_is_its_logs_rotor_table():
    """The log's CA_ROTORn: four arms at (±0.45, ±0.59) m, each a pair of opposite spins;
    its PZ puts rotors 0-3 below 4-7, so they take the coaxial factors; each layer's spins
    cancel. Its airframe (SYS_AUTOSTART 12001) names it."""
    vehicle = load_vehicle("auriol_x8")
    prop = vehicle.propulsion
    hubs = np.array(prop.position_frd_m)
    np.testing.assert_array_equal(np.abs(hubs[:, :2]), [[0.45, 0.59]] * 8)
    assert prop.coaxial_lower == (True,) * 4 + (False,) * 4
    assert prop.thrust_factors == (0.70,) * 4 + (1.0,) * 4
    for lower in range(4):
        upper = next(u for u in range(4, 8) if np.allclose(hubs[u, :2], hubs[lower, :2]))
        assert hubs[upper, 2] < hubs[lower, 2]
        assert prop.spin_direction[upper] == -prop.spin_direction[lower]
    assert sum(prop.spin_direction[:4]) == sum(prop.spin_direction[4:]) == 0
    assert AIRFRAMES[12001] == "auriol_x8"
    assert vehicle_for_airframe({"SYS_AUTOSTART": 12001.0}, "log") == "auriol_x8"


@pytest.mark.parametrize(
    ("name", "hover_radps"),
    [
        # √(m·g/(Σ thrust factors · C_T)): 2.0 kg on six rotors; 30 kg on 4 + 4 × 0.70.
        ("f550_hexa", 543.89),
        ("auriol_x8", 325.52),
    ],
)
def test_hover_speed_is_the_closed_form(name, hover_radps):
    vehicle = load_vehicle(name)
    prop = vehicle.propulsion
    weight = vehicle.body.mass_kg * G
    closed_form = math.sqrt(
        weight / (sum(prop.thrust_factors) * prop.thrust_coefficient_n_per_radps2)
    )
    assert closed_form == pytest.approx(hover_radps, abs=0.01)
    assert vehicle.hover_rotor_speed_radps == pytest.approx(closed_form, rel=1e-12)


def test_the_x8_hovers_at_its_logs_hover_throttle():
    """Its data: PX4's hover command MPC_THR_HOVER 0.57 is ESC throttle 0.15 + 0.85·0.57 =
    0.634 through DShot's floor; on the speed curve (at its voltage) that is the hover speed."""
    prop = load_vehicle("auriol_x8").propulsion
    hover = load_vehicle("auriol_x8").hover_rotor_speed_radps
    throttle = (hover - prop.speed_offset_radps) / prop.speed_slope_radps
    dshot_floor = 299.0 / 1999.0  # DSHOT_MIN 0.15 of the driver's 1999
    assert throttle == pytest.approx(dshot_floor + (1 - dshot_floor) * 0.57, abs=0.002)


@pytest.mark.parametrize(
    ("name", "low", "high"),
    [
        # The hexa: 0.45 on its charged 4S (about 16 V under load against the curve's 11.1 V).
        ("f550_hexa", 0.4, 0.6),
        # The X8: 0.65, its log's 0.634 at ISA sea level with the charged 12S sagging to the
        # curve's 48 V under the hover's 130 A; the home's 488 m make the rotors 2.4 % faster.
        ("auriol_x8", 0.63, 0.67),
    ],
)
def test_the_model_holds_a_hover_with_every_moment_balanced(rng, name, low, high):
    """At the model's hover throttle every rotor turns at the closed-form speed in the air
    there, the thrusts sum to the weight and the vehicle stays put, neither turning nor
    yawing: the spins (and the X8's lower rotors of both spins) cancel."""
    vehicle = load_vehicle(name)
    prop = vehicle.propulsion
    home = Environment().home.alt_amsl_m
    density_ratio = isa_density_kgpm3(home + HOVER_ALTITUDE_M) / prop.reference_air_density_kgpm3
    factors = np.array(prop.thrust_factors)
    ct = prop.thrust_coefficient_n_per_radps2 * density_ratio
    speed = math.sqrt(vehicle.body.mass_kg * G / (factors.sum() * ct))
    model = QuadModel(vehicle, rng)
    model.reset(position_ned_m=(0, 0, -HOVER_ALTITUDE_M), rotor_speed_radps=speed)
    throttle = model.hover_throttle()
    assert low < throttle < high
    model.advance([throttle] * prop.rotor_count, 0.5)
    truth = model.truth
    np.testing.assert_allclose(truth.rotor_speed_radps, speed, rtol=2e-4)
    np.testing.assert_allclose(truth.rotor_thrust_n, factors * ct * speed**2, rtol=5e-4)
    assert truth.rotor_thrust_n.sum() == pytest.approx(vehicle.body.mass_kg * G, rel=5e-4)
    np.testing.assert_allclose(truth.position_ned_m, [0, 0, -HOVER_ALTITUDE_M], atol=2e-3)
    np.testing.assert_allclose(truth.angular_rate_frd_radps, 0.0, atol=1e-9)
    np.testing.assert_allclose(truth.moment_frd_nm, 0.0, atol=1e-9)
