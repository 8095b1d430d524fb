"""Campaign files, case expansion, pass criteria and metrics (no runs: fast)."""

import hashlib
import math

import numpy as np
import pytest

from rig.campaign import CampaignError, Criterion, campaign_from_dict, expand, load_campaign
from rig.campaign.case import credibility_metrics, tilt_from_level_deg
from rig.errors import ScenarioError


def document(**overrides):
    base = {
        "name": "t",
        "scenario": "takeoff_hover_land",
        "duration_s": 3.0,
        "axes": {
            "fault": ["none", "m0"],
            "fault_onset_s": [1.0, 2.0],
            "mass_scale": [1.0, 1.2],
            "wind_north_mps": [3.0],
            "seed": [4],
        },
        "faults": {
            "m0": {"kind": "motor_degradation", "motor": 0, "severity": "efficiency",
                   "efficiency": [0.5, 0.8], "duration_s": 0.5},
        },
        "criteria": {"max_tilt_deg": {"max": 30.0}, "crashed": {"equals": False}},
    }  # fmt: skip
    return {**base, **overrides}


def test_cases_are_the_cartesian_product_with_severities_and_onsets_applied(tmp_path):
    campaign = campaign_from_dict(document(), "c.toml")
    cases = expand(campaign, tmp_path)
    assert len(cases) == 3 * 2 * 2  # fault (none + 2 severities) × onset × mass
    assert len({case.case_id for case in cases}) == len(cases)
    labels = [dict(case.labels) for case in cases]
    assert labels[0] == {"fault": "none", "fault_onset_s": "1", "mass_scale": "1",
                         "wind_north_mps": "3", "seed": "4"}  # fmt: skip
    degraded = next(c for c, lab in zip(cases, labels, strict=True)
                    if lab["fault"] == "m0 efficiency=0.8" and lab["fault_onset_s"] == "2"
                    and lab["mass_scale"] == "1.2")  # fmt: skip
    assert degraded.scenario_document["faults"] == [
        {"kind": "motor_degradation", "motor": 0, "efficiency": 0.8, "start_s": 2.0, "end_s": 2.5}
    ]
    assert degraded.onset_s == 2.0
    assert degraded.scenario_document["seed"] == 4
    assert degraded.scenario_document["duration_s"] == 3.0
    assert degraded.scenario_document["environment"]["wind"]["steady_ned_mps"] == [3.0, 0.0, 0.0]
    # The F450 file's 1.4 kg, scaled; the inertia untouched.
    assert degraded.vehicle_document["body"]["mass_kg"] == pytest.approx(1.4 * 1.2)
    assert degraded.vehicle_document["body"]["inertia_kgm2"][0][0] == 0.0211
    assert "faults" not in cases[0].scenario_document  # the takeoff_hover_land file has none


def test_case_ids_are_stable_so_a_rerun_finds_its_cases(tmp_path):
    first = [c.case_id for c in expand(campaign_from_dict(document(), "c.toml"), tmp_path)]
    again = [c.case_id for c in expand(campaign_from_dict(document(), "c.toml"), tmp_path)]
    assert first == again


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"axes": {"colour": [1]}}, "c.toml: key 'axes.colour' = [1]: unknown key"),
        ({"axes": {"seed": [-1]}}, "c.toml: key 'axes.seed[0]' = -1: expected a value >= 0"),
        (
            {"axes": {"fault": ["nope"]}},
            "c.toml: key 'axes.fault' = 'nope': no [faults.nope] table",
        ),
        (
            {"axes": {"mass_scale": []}},
            "c.toml: key 'axes.mass_scale' = []: expected at least 1 item(s)",
        ),
        ({"sensor_layer": "fpga"}, "c.toml: key 'sensor_layer' = 'fpga': expected 'tlm' or 'rtl'"),
        (
            {"criteria": {"crashed": {"max": 1}}},
            "c.toml: key 'criteria.crashed' = {'max': 1.0}: expected {equals = true|false}",
        ),
        (
            {"criteria": {"speed": {"max": 1}}},
            "c.toml: key 'criteria.speed' = {'max': 1}: expected 'max_tilt_deg', ",
        ),
        ({"case_timeout_s": 0}, "c.toml: key 'case_timeout_s' = 0: expected a value > 0"),
        (
            {"instances": 90},
            "c.toml: key 'instances' = 90: first_instance (20) + instances must lie within",
        ),
        ({"scenario": "no_such"}, "no_such.toml: no such scenario file (bundled: "),
        (
            {"faults": {"m0": {"kind": "motor_loss", "motor": 8}}, "axes": {"fault": ["m0"]}},
            "c.toml: faults.m0: key 'motor' = 8: expected a value <= 7",
        ),
        (
            {"faults": {"m0": {"kind": "motor_loss", "motor": 0, "duration_s": "3"}}},
            "c.toml: faults.m0: key 'duration_s' = '3': expected a valid number",
        ),
    ],
)
def test_bad_campaign_files_fail_with_one_line_naming_key_and_value(overrides, message):
    with pytest.raises(CampaignError) as error:
        campaign_from_dict(document(**overrides), "c.toml")
    assert message in str(error.value)
    assert "\n" not in str(error.value)


def test_a_case_that_makes_a_bad_scenario_is_named_by_its_axis_values():
    """An onset after the end of the run is refused before anything runs."""
    with pytest.raises(ScenarioError, match=r"case 1 \(fault=m0 efficiency=0.5, fault_onset_s=5"):
        campaign_from_dict(document(axes={"fault": ["m0"], "fault_onset_s": [1.0, 5.0]}), "c.toml")


def test_a_severity_must_name_a_listed_parameter_of_the_fault():
    faults = {"m0": {"kind": "motor_loss", "motor": 0, "severity": "motor"}}
    with pytest.raises(CampaignError, match=r"key 'faults\.m0\.severity' = 'motor': expected a"):
        campaign_from_dict(document(faults=faults, axes={"fault": ["m0"]}), "c.toml")


def test_criteria_bounds_equality_and_missing_values():
    tilt = Criterion("max_tilt_deg", maximum=30.0)
    assert tilt.violation(29.9) is None
    assert tilt.violation(31.0) == "max_tilt_deg = 31 > 30"
    failsafe = Criterion("time_to_failsafe_s", minimum=0.0, maximum=2.0)
    assert failsafe.violation(None) == "time_to_failsafe_s not measured (none in the run)"
    assert failsafe.violation(1.0) is None
    assert Criterion("crashed", equals=False).violation(True) == "crashed = True != False"


def test_tilt_from_level_matches_closed_form_rotations():
    """A rotation by θ about a horizontal axis tilts the body by θ; a yaw does not tilt."""
    angles = np.radians([0.0, 10.0, 45.0, 90.0, 150.0])
    roll = tilt_from_level_deg(np.cos(angles / 2), np.sin(angles / 2), 0 * angles, 0 * angles)
    np.testing.assert_allclose(roll, np.degrees(angles), atol=1e-6)
    # About the horizontal axis (1, 1, 0)/√2, then a yaw: still θ from level.
    s = np.sin(angles / 2) / math.sqrt(2)
    pitch_roll = tilt_from_level_deg(np.cos(angles / 2), s, s, 0 * angles)
    np.testing.assert_allclose(pitch_roll, np.degrees(angles), atol=1e-6)
    yaw = tilt_from_level_deg(np.cos(angles / 2), 0 * angles, 0 * angles, np.sin(angles / 2))
    np.testing.assert_allclose(yaw, 0.0, atol=1e-6)


# -- [credibility] -----------------------------------------------------------------------


def small_plan(tmp_path, real_log, segment_s=(105.0, 106.9)):
    """A one-test plan on a real log: the gyro σ with the motors stopped (quad4001)."""
    plan = tmp_path / "plan.toml"
    plan.write_text(
        f'[logs]\nreal = "{real_log}"\nsim = "{real_log}"\n'
        '[[tests]]\nname = "gyro_sigma"\nkind = "performance"\nparameter = "std"\n'
        f'signal = "sensor_combined.gyro_rad[0]"\nsegment_s = {list(segment_s)}\n'
    )
    return plan


def test_credibility_plan_is_found_beside_the_campaign_or_bundled(tmp_path, quad4001_log):
    plan = small_plan(tmp_path, quad4001_log)
    campaign = campaign_from_dict(
        document(credibility={"plan": "plan.toml", "role": "real", "log": "rig"}),
        str(tmp_path / "c.toml"),
    )
    scoring = campaign.credibility
    assert scoring.plan_path == str(plan.resolve())
    assert scoring.plan_sha256 == hashlib.sha256(plan.read_bytes()).hexdigest()
    assert (scoring.role, scoring.log) == ("real", "rig")
    assert all(case.credibility == scoring for case in expand(campaign, tmp_path))
    bundled = campaign_from_dict(
        document(credibility={"plan": "quad4001_repeatability"}), str(tmp_path / "c.toml")
    ).credibility
    assert bundled.plan_path.endswith("credibility/plans/quad4001_repeatability.toml")
    assert (bundled.role, bundled.log) == ("sim", "autopilot")  # the defaults
    assert campaign_from_dict(document(), "c.toml").credibility is None


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"plan": "nope.toml"}, "key 'credibility.plan' = 'nope.toml': no such plan file"),
        ({"plan": 3}, "key 'credibility.plan' = 3: expected a valid string"),
        ({"plan": "plan.toml", "role": "gazebo"},
         "key 'credibility.role' = 'gazebo': not a log role of the plan (real, sim)"),
        ({"plan": "plan.toml", "log": "px4"},
         "key 'credibility.log' = 'px4': expected 'rig' or 'autopilot'"),
        ({"plan": "plan.toml", "weight": 1}, "key 'credibility.weight' = 1: unknown key"),
        ({"plan": "broken.toml"}, "key 'credibility.plan' = 'broken.toml': "),
    ],
)  # fmt: skip
def test_bad_credibility_tables_fail_at_load_with_one_line(tmp_path, quad4001_log, table, message):
    small_plan(tmp_path, quad4001_log)
    (tmp_path / "broken.toml").write_text("[logs]\nreal = 'x.ulg'\n")  # no [[tests]]
    with pytest.raises(CampaignError) as error:
        campaign_from_dict(document(credibility=table), str(tmp_path / "c.toml"))
    assert message in str(error.value)
    assert "\n" not in str(error.value)


def test_eta_criteria_need_a_credibility_table(tmp_path, quad4001_log):
    criteria = {"eta_min": {"min": 0.6}}
    with pytest.raises(CampaignError, match=r"'criteria\.eta_min' = \{'min': 0\.6\}: needs a \["):
        campaign_from_dict(document(criteria=criteria), "c.toml")
    small_plan(tmp_path, quad4001_log)
    campaign = campaign_from_dict(
        document(criteria=criteria, credibility={"plan": "plan.toml"}), str(tmp_path / "c.toml")
    )
    assert campaign.criteria == (Criterion("eta_min", minimum=0.6),)
    assert (
        Criterion("eta_min", minimum=0.6).violation(None)
        == "eta_min not measured (none in the run)"
    )


def test_identical_logs_score_one_and_a_segment_past_the_log_is_a_reason(tmp_path, quad4001_log):
    """η = 1 for zero error (the log in both roles); a plan that cannot score the case's
    log leaves the indices missing with the plan's own one-line reason."""
    plan = str(small_plan(tmp_path, quad4001_log))
    scores, note = credibility_metrics(
        {"rig": quad4001_log, "autopilot": None}, plan, role="sim", log="rig"
    )
    assert scores == {"eta_all": 1.0, "eta_min": 1.0}
    assert note is None
    scores, note = credibility_metrics(
        {"rig": quad4001_log, "autopilot": None}, plan, role="sim", log="autopilot"
    )
    assert scores == {"eta_all": None, "eta_min": None}
    assert note == "credibility not assessed: the run wrote no autopilot.ulg"
    late = str(small_plan(tmp_path, quad4001_log, segment_s=(5000.0, 5001.0)))
    scores, note = credibility_metrics(
        {"rig": quad4001_log, "autopilot": None}, late, role="sim", log="rig"
    )
    assert scores == {"eta_all": None, "eta_min": None}
    assert note.startswith("credibility not assessed: ")
    assert "5000" in note
    assert "\n" not in note


def test_bundled_campaigns_load_and_the_credibility_example_finds_its_plan():
    assert load_campaign("motor_faults").credibility is None
    example = load_campaign("imu_noise_credibility")
    assert example.credibility.plan_path.endswith(
        "rig/campaign/campaigns/plans/quad4001_hover_vibration.toml"
    )
    assert (example.credibility.role, example.credibility.log) == ("sim", "rig")
    assert Criterion("eta_min", minimum=0.6) in example.criteria
