"""A campaign scored with a credibility plan, on real runs (reference autopilot, TLM
chips, IMU 250 Hz, 3 s each). The plan's reference is a first run's log; a case flown with
the same seed reproduces it exactly (the rig is deterministic), so it scores η = 1, and a
case with another seed differs in its noise and scores below 1."""

import json

import pytest

from rig.campaign import (
    CampaignError,
    campaign_executor,
    campaign_from_dict,
    read_provenance,
    read_results,
    run_campaign,
)
from rig.campaign.report import write_report
from tests.instances import worker_instances

pytestmark = pytest.mark.closed_loop
#: This worker's instances (tests.instances): campaigns of two workers never share one.
CAMPAIGN_INSTANCES = worker_instances(20, 40)

SCENARIO = (
    'name = "short_hover"\nvehicle = "f450_high_precision"\nduration_s = 3.0\nseed = 1\n'
    "[rates]\nimu_hz = 250\n"
    '[[commands]]\nat_s = 0.2\naction = "arm"\n'
    '[[commands]]\nat_s = 0.3\naction = "takeoff"\naltitude_m = 2.0\n'
)


def plan_text(reference, segment_s):
    """The climb's altitude curve (η_t) and the gyro noise σ (η_p) of the ground truth."""
    return (
        f'[logs]\nreal = "{reference}"\nsim = "{reference}"\n'
        '[[tests]]\nname = "climb"\nkind = "time"\n'
        f'signal = "vehicle_local_position_groundtruth.z"\nsegment_s = {segment_s}\n'
        'unit = "m"\n'
        '[[tests]]\nname = "gyro_sigma"\nkind = "performance"\nparameter = "std"\n'
        f'signal = "sensor_combined.gyro_rad[0]"\nsegment_s = {segment_s}\n'
    )


def campaign(tmp_path, seeds, credibility=None, criteria=None):
    document = {
        "name": "scored",
        "scenario": str(tmp_path / "short_hover.toml"),
        "case_timeout_s": 60.0,
        "first_instance": CAMPAIGN_INSTANCES.start,
        "instances": len(CAMPAIGN_INSTANCES),
        "axes": {"seed": seeds},
        **({"credibility": credibility} if credibility else {}),
        **({"criteria": criteria} if criteria else {}),
    }
    return campaign_from_dict(document, str(tmp_path / "scored.toml"))


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("scored")
    (tmp_path / "short_hover.toml").write_text(SCENARIO)
    with campaign_executor(workers=2) as executor:
        (reference,) = run_campaign(campaign(tmp_path, [1]), tmp_path / "reference", executor)
        (tmp_path / "plan.toml").write_text(plan_text(reference.rig_log, [0.5, 2.9]))
        (tmp_path / "late.toml").write_text(plan_text(reference.rig_log, [2.0, 9.0]))
        out = tmp_path / "results"
        spec = campaign(
            tmp_path,
            [1, 2],
            credibility={"plan": "plan.toml", "log": "rig"},
            criteria={"eta_min": {"min": 0.999}},
        )
        run_campaign(spec, out, executor)
    return tmp_path, reference, spec, out


def test_same_seed_scores_one_and_another_seed_less(scored):
    _, _, _, out = scored
    by_seed = {dict(r.labels)["seed"]: r for r in read_results(out)}
    same, other = by_seed["1"], by_seed["2"]
    assert same.status == "ok"
    assert same.metrics["eta_all"] == pytest.approx(1.0, abs=1e-9)
    assert same.metrics["eta_min"] == pytest.approx(1.0, abs=1e-9)
    assert 0.0 <= other.metrics["eta_min"] < 1.0
    assert other.metrics["eta_min"] <= other.metrics["eta_all"] < 1.0
    assert other.status == "failed"
    assert other.reason.startswith("eta_min = ")
    assert other.reason.endswith("< 0.999")


def test_plan_hash_is_recorded_once_and_shown_in_the_report(scored):
    _, _, spec, out = scored
    provenance = read_provenance(out)
    assert provenance["credibility_plan_sha256"] == spec.credibility.plan_sha256
    assert provenance["credibility_role"] == "sim"
    html = write_report(out).read_text()
    assert spec.credibility.plan_sha256 in html
    assert "eta_min mean / min" in html
    report = json.loads((out / "report.json").read_text())
    seeds = {row["value"]: row for row in report["axes"]["seed"]}
    assert seeds["1"]["eta_min"]["min"] == pytest.approx(1.0, abs=1e-9)


def test_a_plan_the_case_log_cannot_fill_leaves_the_index_missing_with_its_reason(scored):
    """The segment runs past the 3 s run: each case records why, the campaign goes on."""
    tmp_path, _, _, _ = scored
    out = tmp_path / "late"
    spec = campaign(tmp_path, [1], credibility={"plan": "late.toml", "log": "rig"})
    with campaign_executor(workers=1) as executor:
        (result,) = run_campaign(spec, out, executor)
    assert result.status == "ok"  # no criterion asked for the index
    assert result.metrics["eta_all"] is None
    assert result.metrics["eta_min"] is None
    assert result.reason.startswith("credibility not assessed: ")
    assert result.metrics["max_tilt_deg"] < 15.0  # the other metrics are all there


def test_a_changed_plan_is_refused_for_results_scored_with_the_old_one(scored):
    tmp_path, _, _, out = scored
    plan = tmp_path / "plan.toml"
    plan.write_text(plan.read_text() + "# edited\n")
    spec = campaign(tmp_path, [1, 2], credibility={"plan": "plan.toml", "log": "rig"})
    with campaign_executor(workers=1) as executor, pytest.raises(CampaignError) as error:
        run_campaign(spec, out, executor)
    assert "were scored with credibility plan sha256" in str(error.value)
    assert "use a new results folder" in str(error.value)
