"""PX4 parameter table: PX4's names, defaults and ranges; checked changes."""

import pytest

from rig.autopilots.reference.params import PARAMETERS, ParameterError, Parameters, parse_assignment


def test_names_fit_mavlink_param_id_and_are_unique():
    names = [spec.name for spec in PARAMETERS]
    assert len(names) == len(set(names))
    assert all(len(name) <= 16 for name in names)


@pytest.mark.parametrize(
    ("name", "px4_default"),
    [  # values from PX4-Autopilot main *_params.yaml
        ("MC_ROLLRATE_P", 0.15), ("MC_ROLLRATE_I", 0.2), ("MC_ROLLRATE_D", 0.003),
        ("MC_YAWRATE_P", 0.2), ("MC_YAW_P", 2.8), ("MC_YAW_WEIGHT", 0.4),
        ("MC_ROLLRATE_MAX", 220.0), ("MPC_XY_P", 0.95), ("MPC_XY_VEL_P_ACC", 1.8),
        ("MPC_Z_VEL_P_ACC", 4.0), ("MPC_Z_VEL_I_ACC", 2.0), ("MPC_THR_HOVER", 0.5),
        ("MPC_TILTMAX_AIR", 45.0), ("MPC_LAND_SPEED", 0.7), ("MIS_TAKEOFF_ALT", 2.5),
        ("NAV_MC_ALT_RAD", 0.8), ("ATT_W_ACC", 0.2), ("ATT_W_MAG", 0.1),
    ],
)  # fmt: skip
def test_px4_defaults(name, px4_default):
    assert Parameters()[name] == pytest.approx(px4_default)


def test_set_checks_range_and_type_and_counts_versions():
    params = Parameters()
    version = params.version
    assert params.set("MPC_XY_P", 1.2) == pytest.approx(1.2)
    assert params.version == version + 1
    params.set("MPC_XY_P", 1.2)  # no change, no new version
    assert params.version == version + 1
    with pytest.raises(ParameterError, match=r"parameter MPC_XY_P: 3\.0 outside 0\.0\.\.2\.0"):
        params.set("MPC_XY_P", 3.0)
    with pytest.raises(ParameterError, match=r"parameter SYS_HAS_MAG: 0\.5 is not an integer"):
        params.set("SYS_HAS_MAG", 0.5)
    with pytest.raises(ParameterError, match=r"unknown parameter 'NOPE'"):
        params.set("NOPE", 1)


def test_overrides_and_command_line_assignment():
    assert parse_assignment("MPC_XY_P=1.5") == ("MPC_XY_P", 1.5)
    assert Parameters({"MPC_XY_P": 1.5})["MPC_XY_P"] == pytest.approx(1.5)
    with pytest.raises(ParameterError, match=r"--param 'MPC_XY_P': expected NAME=VALUE"):
        parse_assignment("MPC_XY_P")
    with pytest.raises(ParameterError, match=r"value 'x' is not a number"):
        parse_assignment("MPC_XY_P=x")


def test_index_round_trip():
    params = Parameters()
    for i, name in enumerate(params):
        assert params.index(name) == i
        assert params.name_at(i) == name
    with pytest.raises(ParameterError, match="out of range"):
        params.name_at(len(params))
