"""The credibility study in miniature (issue #8): the real X500 flight's first half-minute
replayed by the high- and the low-precision model, scored by the shipped study plan's own
tests that fall inside that span (armed idle on the ground, the take-off climb, the hover).

These check properties the study must have, not numbers of one run: the identified model
scores above the analytic one, the paper's zero-output curve sits near 0, and the real flight
against itself scores 1.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from credibility.assess import Assessment, TimeResult, assess
from credibility.plan import load_plan
from rig.apps.replay import ReplayOptions, plan_replay, run_replay
from rig.lockstep.loop import RunOptions
from tests.instances import free_test_instance

REPO = Path(__file__).resolve().parents[2]
STUDY_PLAN = REPO / "credibility/plans/x500_validation.toml"
X500_LOG = REPO / "data/flight_logs/px4_x500v2_v6xrt_flight_2026-03-20.ulg"
#: The replay stops here: idle 409-411 s, climb 413-419 s and hover 420-436 s are inside.
END_S = 437.0
MODELS = {"high": "x500_v2", "low": "x500_v2_low_precision"}


@pytest.fixture(scope="module")
def replays(tmp_path_factory) -> dict[str, Path]:
    """The velocity-drive replay of 407.4-437 s by each model: its autopilot log."""
    logs = {}
    for model, vehicle in MODELS.items():
        plan = plan_replay(X500_LOG, ReplayOptions(end_s=END_S, vehicle=vehicle, seed=8))
        out = tmp_path_factory.mktemp(f"replay_{model}")
        result = run_replay(plan, RunOptions(instance=free_test_instance(), out_dir=out))
        logs[model] = result.autopilot_log
    return logs


def _study(real: Path, sim: Path, sim_low: Path) -> Assessment:
    """The shipped plan's velocity-drive tests that end by END_S, scoring ``sim``."""
    plan = load_plan(STUDY_PLAN, {"real": real, "sim": sim, "sim_low": sim_low})
    tests = tuple(
        t for t in plan.tests
        if t.roles.sim == "sim" and t.segment_s is not None and t.segment_s[1] <= END_S
    )  # fmt: skip
    logs = {role: plan.logs[role] for role in ("real", "sim", "sim_low")}
    kinds = {t.kind for t in tests}
    weights = {kind: w for kind, w in plan.weights.items() if kind in kinds}  # paper's, renormed
    weights = {kind: w / sum(weights.values()) for kind, w in weights.items()}
    return assess(dataclasses.replace(plan, tests=tests, logs=logs, weights=weights))


@pytest.fixture(scope="module")
def scored(replays) -> dict[str, Assessment]:
    high, low = replays["high"], replays["low"]
    return {"high": _study(X500_LOG, high, low), "low": _study(X500_LOG, low, high)}


def test_the_span_holds_every_kind_of_test_of_the_study(scored):
    kinds = {r.test.kind for r in scored["high"].results}
    assert {"performance", "time"} <= kinds
    assert len(scored["high"].results) >= 8


def test_the_identified_model_is_more_credible_than_the_analytic_one(scored):
    """The paper's claim for its Table 2, on real data: η ranks the models by precision."""
    assert scored["high"].eta_all > scored["low"].eta_all


def test_the_zero_output_curve_scores_near_zero(scored):
    """The paper's Table 2 worst case: a curve that never moves (η_t = 1.75 % there)."""
    rows = [r for r in scored["high"].results if isinstance(r, TimeResult)]
    assert rows
    for row in rows:
        assert row.zero_output_eta < 0.1, row.test.name


def test_the_real_flight_scores_one_against_itself():
    same = _study(X500_LOG, X500_LOG, X500_LOG)
    assert same.eta_all == pytest.approx(1.0)
