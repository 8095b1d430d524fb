"""Hexas and octos, flat and coaxial, against closed-form cases: the same kernel as the quad."""

import dataclasses
import math

import numpy as np
import pytest

from quad_model import ModelInputError, Mount, QuadBatch, QuadModel, Vehicle
from quad_model.environment import Environment, isa_density_kgpm3
from quad_model.frames import STANDARD_GRAVITY_MPS2
from quad_model.vehicle import VehicleFileError, vehicle_from_dict

G = STANDARD_GRAVITY_MPS2
ARM_M = 0.25


def _flat(count: int) -> tuple[list[list[float]], list[float]]:
    """A flat frame of ``count`` arms, rotors alternating in spin around the circle."""
    angles = [math.pi / count + 2 * math.pi * k / count for k in range(count)]
    hubs = [[ARM_M * math.cos(a), ARM_M * math.sin(a), -0.04] for a in angles]
    return hubs, [1.0 if k % 2 == 0 else -1.0 for k in range(count)]


def _x8() -> tuple[list[list[float]], list[float]]:
    """A coaxial X8: four arms, an upper rotor (0-3) above a lower one (4-7) of the other
    spin on each."""
    arms = [(1, 1), (-1, -1), (1, -1), (-1, 1)]  # quad-X order
    upper_spin = [1.0, 1.0, -1.0, -1.0]
    hubs = [[ARM_M * x / math.sqrt(2), ARM_M * y / math.sqrt(2), -0.10] for x, y in arms]
    hubs += [[hx, hy, 0.0] for hx, hy, _ in hubs]
    return hubs, upper_spin + [-s for s in upper_spin]


def frame(base: Vehicle, hubs: list[list[float]], spins: list[float], **propulsion) -> Vehicle:
    """``base`` with another rotor table (and propulsion keys), through the file schema."""
    document = dataclasses.asdict(base)
    document["propulsion"] |= {"position_frd_m": hubs, "spin_direction": spins} | propulsion
    if document["rangefinder"] is None:  # a TOML file leaves an absent table out
        del document["rangefinder"]
    return vehicle_from_dict(document, f"<{len(hubs)} rotors>")


FRAMES = {
    "quad": lambda v: frame(v, *_flat(4)),
    "hexa": lambda v: frame(v, *_flat(6)),
    "octo": lambda v: frame(v, *_flat(8)),
    "x8": lambda v: frame(v, *_x8(), coaxial_thrust_factor=0.8, coaxial_torque_factor=0.9),
}


def _density_ratio(vehicle: Vehicle) -> float:
    home = Environment().home.alt_amsl_m
    return isa_density_kgpm3(home + 10.0) / vehicle.propulsion.reference_air_density_kgpm3


@pytest.mark.parametrize("name", FRAMES)
def test_hover_at_the_closed_form_rotor_speed_with_yaw_balanced(x500, rng, name):
    vehicle = FRAMES[name](x500)
    prop = vehicle.propulsion
    factors = np.array(prop.thrust_factors)
    ct = prop.thrust_coefficient_n_per_radps2 * _density_ratio(vehicle)
    predicted = math.sqrt(vehicle.body.mass_kg * G / (factors.sum() * ct))
    model = QuadModel(vehicle, rng)
    model.reset(position_ned_m=(0, 0, -10), rotor_speed_radps=predicted)
    model.advance([model.hover_throttle()] * prop.rotor_count, 0.5)
    truth = model.truth
    np.testing.assert_allclose(truth.rotor_speed_radps, predicted, rtol=2e-4)
    np.testing.assert_allclose(truth.rotor_thrust_n, factors * ct * predicted**2, rtol=5e-4)
    assert truth.rotor_thrust_n.sum() == pytest.approx(vehicle.body.mass_kg * G, rel=5e-4)
    np.testing.assert_allclose(truth.position_ned_m, [0, 0, -10], atol=2e-3)
    # Alternating spins (and, on the X8, lower rotors of both spins) cancel the torques.
    np.testing.assert_allclose(truth.angular_rate_frd_radps, 0.0, atol=1e-9)
    assert abs(truth.moment_frd_nm[2]) < 1e-9


@pytest.mark.parametrize("name", FRAMES)
def test_thrust_stand_forces_and_moments_are_the_rotor_sums(x500, rng, name):
    vehicle = FRAMES[name](x500)
    prop = vehicle.propulsion
    count = prop.rotor_count
    model = QuadModel(vehicle, rng, mount=Mount.THRUST_STAND)
    throttles = np.linspace(0.3, 0.8, count)
    model.advance(throttles, 0.5)
    truth = model.truth
    w = truth.rotor_speed_radps
    ratio = isa_density_kgpm3(Environment().home.alt_amsl_m) / prop.reference_air_density_kgpm3
    thrust = np.array(prop.thrust_factors) * prop.thrust_coefficient_n_per_radps2 * ratio * w**2
    torque = np.array(prop.torque_factors) * prop.torque_coefficient_nm_per_radps2 * ratio * w**2
    np.testing.assert_allclose(truth.rotor_thrust_n, thrust, rtol=1e-12)
    np.testing.assert_allclose(truth.rotor_torque_nm, torque, rtol=1e-12)
    hubs = np.array(prop.position_frd_m)
    spin = np.array(prop.spin_direction)
    moment = [
        -(hubs[:, 1] * thrust).sum(),
        (hubs[:, 0] * thrust).sum(),
        (spin * torque).sum(),
    ]
    np.testing.assert_allclose(truth.force_frd_n, [0, 0, -thrust.sum()], atol=1e-12)
    np.testing.assert_allclose(truth.moment_frd_nm, moment, rtol=5e-4, atol=1e-9)


def test_coaxial_lower_rotors_are_found_from_the_hubs(x500):
    vehicle = FRAMES["x8"](x500)
    assert vehicle.propulsion.coaxial_lower == (False,) * 4 + (True,) * 4
    assert vehicle.propulsion.thrust_factors == (1.0,) * 4 + (0.8,) * 4
    assert FRAMES["octo"](x500).propulsion.coaxial_lower == (False,) * 8


def test_a_batch_of_mixed_rotor_counts_gives_each_vehicle_its_numbers_alone(x500):
    vehicles = [FRAMES[name](x500) for name in ("quad", "x8", "hexa", "quad", "octo")] * 2
    batch = QuadBatch(vehicles, len(vehicles), np.random.default_rng(1))
    assert batch.rotors == 8
    commands = np.linspace(0.55, 0.65, 8)
    batch.reset(position_ned_m=(0, 0, -5))
    batch.advance(np.tile(commands, (len(vehicles), 1)), 0.3)
    for k, vehicle in enumerate(vehicles):
        alone = QuadModel(vehicle, np.random.default_rng(1))
        alone.reset(position_ned_m=(0, 0, -5))
        alone.advance(commands[: vehicle.propulsion.rotor_count], 0.3)
        np.testing.assert_array_equal(batch.states[k], alone._batch.states[0])
        np.testing.assert_array_equal(batch.outputs[k], alone._batch.outputs[0])


def test_any_motor_of_an_octo_can_fail_and_no_motor_past_a_quads(x500, rng):
    octo = QuadModel(FRAMES["octo"](x500), rng, mount=Mount.THRUST_STAND)
    octo.set_motor_health(7, 0.0)
    octo.advance([0.6] * 8, 0.5)
    assert octo.truth.rotor_thrust_n[7] == 0.0
    assert octo.truth.rotor_thrust_n[6] > 1.0
    quad = QuadModel(x500, rng)
    with pytest.raises(ModelInputError, match=r"motor=4 must be within 0..3"):
        quad.set_motor_health(4, 0.0)
    with pytest.raises(ModelInputError, match=r"is not 4 throttles"):
        quad.advance([0.5] * 8, 0.001)


@pytest.mark.parametrize(
    ("hubs", "spins", "message"),
    [
        (_flat(5)[0], _flat(5)[1], r"position_frd_m.*has 5 rotors; the model flies 4, 6, 8"),
        (_flat(6)[0], [1.0, -1.0] * 2, r"spin_direction.*needs one entry per rotor .*\(6\)"),
    ],
)
def test_rotor_tables_the_model_cannot_fly_are_one_line(x500, hubs, spins, message):
    with pytest.raises(VehicleFileError, match=message) as error:
        frame(x500, hubs, spins)
    assert "\n" not in str(error.value)
