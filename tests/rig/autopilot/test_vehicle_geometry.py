"""The rig gives the reference autopilot the vehicle's rotor geometry, as a PX4 airframe file
configures CA_ROTORi_*; an explicit --param (a replay's log geometry) wins."""

import numpy as np
import pytest

from quad_model import load_vehicle
from rig.autopilot.control import ControlAllocator
from rig.autopilot.params import Parameters, parse_assignment
from rig.loop import reference_autopilot_params

VEHICLES = ("f450_high_precision", "x500_v2")


def _parameters(texts: tuple[str, ...]) -> Parameters:
    """As ``python -m rig.autopilot`` reads its ``--param`` list."""
    return Parameters(dict(parse_assignment(text) for text in texts))


@pytest.mark.parametrize("name", VEHICLES)
def test_geometry_is_the_vehicle_files(name):
    """PX/PY are the hub positions (forward, right) in PX4's motor order; KM is the rotor's
    torque/thrust coefficient ratio, signed + for the CCW rotors (0 and 1 on a quad X)."""
    propulsion = load_vehicle(name).propulsion
    params = _parameters(reference_autopilot_params(load_vehicle(name), ()))
    ratio = propulsion.torque_coefficient_nm_per_radps2 / propulsion.thrust_coefficient_n_per_radps2
    for i, (x, y, _) in enumerate(propulsion.position_frd_m):
        assert params[f"CA_ROTOR{i}_PX"] == x
        assert params[f"CA_ROTOR{i}_PY"] == y
        assert params[f"CA_ROTOR{i}_KM"] == pytest.approx(propulsion.spin_direction[i] * ratio)
    assert [params[f"CA_ROTOR{i}_KM"] > 0 for i in range(4)] == [True, True, False, False]


@pytest.mark.parametrize("name", VEHICLES)
def test_each_torque_command_makes_only_its_own_moment_on_the_vehicle(name):
    """Small-signal about hover (identical rotors: thrust change ∝ throttle change): the
    moment of the allocator's rotor-thrust changes, summed over the vehicle's own hubs
    (r × −T·ẑ, yaw reaction +spin·ratio·T), is along the commanded axis only."""
    vehicle = load_vehicle(name)
    propulsion = vehicle.propulsion
    ratio = propulsion.torque_coefficient_nm_per_radps2 / propulsion.thrust_coefficient_n_per_radps2
    hubs = np.array(propulsion.position_frd_m)
    spin = np.array(propulsion.spin_direction)

    def moments(params: Parameters) -> np.ndarray:
        allocator = ControlAllocator(params)
        hover = allocator.allocate(np.zeros(3), 0.5)
        rows = []
        for axis in np.eye(3) * 0.05:
            thrust = allocator.allocate(axis, 0.5) - hover
            moment = np.cross(hubs, np.outer(-thrust, [0.0, 0.0, 1.0])).sum(axis=0)
            moment[2] += ratio * spin @ thrust
            rows.append(moment)
        return np.array(rows)  # row: commanded axis, column: moment axis

    own = moments(_parameters(reference_autopilot_params(vehicle, ())))
    assert np.all(np.diag(own) > 0)
    off_diagonal = own - np.diag(np.diag(own))
    assert np.abs(off_diagonal).max() < 1e-9 * np.abs(own).max()
    # why the vehicle's geometry matters: 10016's default allocates yaw with more roll than
    # yaw moment on these frames, and roll with 0.69× the pitch authority
    default = moments(Parameters())
    assert abs(default[2, 0]) > 0.5 * default[2, 2]
    assert default[0, 0] < 0.75 * default[1, 1]


def test_an_explicit_param_wins_over_the_vehicle_geometry():
    vehicle = load_vehicle("f450_high_precision")
    explicit = ("CA_ROTOR0_PX=0.2", "CA_ROTOR3_KM=-0.05", "MPC_XY_P=1.0")
    texts = reference_autopilot_params(vehicle, explicit)
    names = [text.partition("=")[0] for text in texts]
    assert len(names) == len(set(names)) == 12 + 1  # 4 rotors × PX/PY/KM, plus MPC_XY_P
    params = _parameters(texts)
    assert params["CA_ROTOR0_PX"] == 0.2
    assert params["CA_ROTOR3_KM"] == -0.05
    assert params["MPC_XY_P"] == 1.0
    assert params["CA_ROTOR0_PY"] == vehicle.propulsion.position_frd_m[0][1]
