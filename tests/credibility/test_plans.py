"""The plans shipped in credibility/plans run on the carried real logs."""

from pathlib import Path

import pytest

import credibility
from credibility.assess import assess
from credibility.plan import load_plan

PLANS = Path(credibility.__file__).parent / "plans"


@pytest.mark.parametrize(
    "name", ["paper_sensor_noise", "paper_frequency_sweep", "paper_level_flight"]
)
def test_paper_plans_score_a_log_against_itself_as_one(name):
    """Until the rig writes its runs, the real log stands in for every sim role: every
    signal path and segment of the plan must resolve, and identical logs must give η = 1."""
    plan = load_plan(PLANS / f"{name}.toml")
    real = plan.logs["real"]
    plan = load_plan(PLANS / f"{name}.toml", {role: real for role in plan.logs if role != "real"})
    result = assess(plan)
    assert result.eta_all == pytest.approx(1.0, abs=1e-12)
    assert result.eta_min == pytest.approx(1.0, abs=1e-12)


def test_repeatability_example_on_the_real_log():
    result = assess(load_plan(PLANS / "quad4001_repeatability.toml"))
    by_name = {r.test.name: r for r in result.results}
    # SOURCES.md: gyro x σ = 0.0031 rad/s with the motors stopped
    assert by_name["gyro_x_sigma_stopped"].rows[0].p_e == pytest.approx(0.0031, rel=0.1)
    # The rate setpoint leads the measured roll rate by a few tens of milliseconds.
    tracking = by_name["roll_rate_tracking"].rows[0]
    assert -0.15 < tracking.alignment_shift_s < -0.02
    # SOURCES.md: roll rate_sp → rate coherence > 0.8 at about 1–3.3 Hz in this hover.
    roll = by_name["roll_rate_response"]
    in_band = (roll.real.freqs_hz > 1.0) & (roll.real.freqs_hz < 3.3)
    assert roll.real.coherence[in_band].min() > 0.7
    assert set(result.means) == {"performance", "time", "frequency"}
    assert 0.0 < result.eta_min <= result.eta_all <= 1.0
