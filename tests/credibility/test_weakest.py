"""The weakest-first page: Theil's decomposition, lags, worst bands and the ranking, each
against a closed form."""

import json
import math

import control
import numpy as np
import pandas as pd
import pytest

from credibility import indices, weakest
from credibility.assess import assess
from credibility.plan import load_plan
from credibility.report import render_html, to_dict
from credibility.spectral import phase_pair_deg

RATE_HZ = 100.0


# --- Theil (1966) proportions ----------------------------------------------------------------


def test_pure_offset_is_all_bias():
    y_e = np.sin(np.linspace(0.0, 20.0, 2001))
    assert indices.theil_decomposition(y_e, y_e + 0.3) == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)


def test_pure_scale_around_the_common_mean_is_all_variance():
    y_e = 2.0 + np.sin(np.linspace(0.0, 20.0, 2001))
    y_s = y_e.mean() + 1.5 * (y_e - y_e.mean())
    assert indices.theil_decomposition(y_e, y_s) == pytest.approx((0.0, 1.0, 0.0), abs=1e-12)


def test_uncorrelated_noise_of_equal_mean_and_sigma_is_all_covariance():
    rng = np.random.default_rng(7)
    u_m, u_s, u_c = indices.theil_decomposition(
        rng.normal(1.0, 0.5, 200_000), rng.normal(1.0, 0.5, 200_000)
    )
    # Sampling leaves mean and σ differences of order σ/sqrt(n): their shares are ~1e-5.
    assert u_c == pytest.approx(1.0, abs=1e-3)
    assert u_m + u_s < 1e-3


def test_offset_and_gain_on_a_sine_split_as_written_out():
    """y_s = a + b·sin: MSE = a² + (b − 1)²/2 over whole periods, r = 1 so U_C = 0."""
    t = np.linspace(0.0, 10.0, 10_000, endpoint=False)  # 10 whole periods of 1 Hz
    a, b = 0.2, 1.4
    mse = a**2 + (b - 1.0) ** 2 / 2.0
    shares = indices.theil_decomposition(np.sin(2 * np.pi * t), a + b * np.sin(2 * np.pi * t))
    assert shares == pytest.approx((a**2 / mse, (b - 1.0) ** 2 / 2.0 / mse, 0.0), abs=1e-9)


def test_a_pure_lag_on_a_sine_is_all_covariance_and_shares_sum_to_one():
    t = np.linspace(0.0, 10.0, 10_000, endpoint=False)
    shares = indices.theil_decomposition(np.sin(2 * np.pi * t), np.sin(2 * np.pi * (t - 0.1)))
    assert shares == pytest.approx((0.0, 0.0, 1.0), abs=1e-9)
    assert sum(shares) == pytest.approx(1.0, abs=1e-12)


def test_identical_curves_have_no_decomposition():
    y = np.arange(5.0)
    assert indices.theil_decomposition(y, y) is None


def test_residual_lag_of_a_delayed_sine():
    grid = np.arange(0.0, 20.0, 1.0 / RATE_HZ)
    lag = weakest.residual_lag_s(grid, np.sin(grid), np.sin(grid - 0.17), max_lag_s=0.5)
    assert lag == pytest.approx(0.17, abs=2e-3)  # sub-sample peak refinement
    assert weakest.residual_lag_s(grid, np.sin(grid), np.sin(grid), 0.5) is None
    assert weakest.residual_lag_s(grid, np.ones_like(grid), np.sin(grid), 0.5) is None


# --- frequency: worst band on constructed FRD pairs -------------------------------------------


FREQS_HZ = np.geomspace(0.1, 10.0, 201)


def _bode(system) -> tuple[np.ndarray, np.ndarray]:
    response = control.frd(system, 2 * np.pi * FREQS_HZ).frdata[0, 0, :]
    return 20 * np.log10(np.abs(response)), response


def test_magnitude_bump_worst_band_is_its_half_maximum_width():
    """sim = real · 10^(A·exp(−ln²(f/f₀)/2s²)/20): a dB bump of height A at f₀ whose
    half-maximum edges are f₀·exp(±s·sqrt(2 ln 2))."""
    s = control.tf("s")
    mag_e, _ = _bode(1 / (s / (2 * np.pi) + 1))
    height_db, f0, width = 4.0, 2.0, 0.4
    bump = height_db * np.exp(-(np.log(FREQS_HZ / f0) ** 2) / (2 * width**2))
    band = weakest.worst_band(FREQS_HZ, (mag_e + bump) - mag_e, np.ones(201), np.ones(201, bool))
    step = FREQS_HZ[1] / FREQS_HZ[0]  # one grid step, as a ratio
    assert band.freq_hz == pytest.approx(f0, rel=step - 1)
    assert band.error == pytest.approx(height_db, rel=1e-3)
    half = width * math.sqrt(2 * math.log(2))
    assert band.band_hz[0] == pytest.approx(f0 * math.exp(-half), rel=step - 1)
    assert band.band_hz[1] == pytest.approx(f0 * math.exp(half), rel=step - 1)


def test_pure_delay_phase_error_peaks_at_the_band_edge():
    """A delay τ adds −360·f·τ degrees: worst at f_b, half of it from f_b/2 up."""
    s = control.tf("s")
    plant = 1 / (s / (2 * np.pi) + 1)
    tau = 0.02
    _, real = _bode(plant)
    _, sim = _bode(plant * control.tf(*control.pade(tau, 8)))
    real_deg, sim_deg = phase_pair_deg(real, sim)
    band = weakest.worst_band(FREQS_HZ, sim_deg - real_deg, np.ones(201), np.ones(201, bool))
    assert band.freq_hz == pytest.approx(10.0)
    assert band.error == pytest.approx(-360 * 10.0 * tau, rel=1e-3)
    assert band.band_hz == pytest.approx((5.0, 10.0), rel=FREQS_HZ[1] / FREQS_HZ[0] - 1)


def test_worst_band_ignores_excluded_points_and_stops_at_them():
    error = np.array([0.0, 1.0, 2.0, 9.0, 2.5, 3.0, 0.5])
    included = np.array([True, True, True, False, True, True, True])
    band = weakest.worst_band(np.arange(1.0, 8.0), error, np.ones(7), included)
    assert band.freq_hz == 6.0  # the 9 at 4.0 Hz is excluded
    assert band.band_hz == (5.0, 6.0)  # 2.5 ≥ 1.5 but the excluded 4.0 Hz ends the run
    weighted = weakest.worst_band(
        np.arange(1.0, 8.0), error, np.r_[1, 1, 2, 1, 1, 0.1, 1], included
    )
    assert weighted.freq_hz == 3.0  # W_γ·|error|: 2·2 beats 0.1·3 and 2.5
    assert weighted.error == 2.0


# --- ranking on a synthetic assessment ---------------------------------------------------------


@pytest.fixture
def logs(tmp_path):
    t = np.arange(0.0, 40.0, 1 / RATE_HZ)
    wave = np.sin(2 * np.pi * 0.5 * t)

    def table(level, big, lag_s, offset):
        return pd.DataFrame(
            {
                "time_s": t,
                "v.level": np.full(t.size, level),
                "v.big": np.full(t.size, big),
                "v.lagged": np.sin(2 * np.pi * 0.5 * (t - lag_s)),
                "v.offset": wave + offset,
            }
        )

    table(10.0, 10.0, 0.0, 0.0).to_csv(tmp_path / "real.csv", index=False)
    table(10.2, 11.0, 0.1, 0.03).to_csv(tmp_path / "sim.csv", index=False)
    table(9.0, 10.1, 0.2, 0.3).to_csv(tmp_path / "sim_low.csv", index=False)
    return tmp_path


PLAN = """
[logs]
real = "real.csv"
sim = "sim.csv"
sim_low = "sim_low.csv"

[[tests]]
name = "level"
kind = "performance"
parameter = "mean"
signal = "v.level"
segment_s = [5.0, 15.0]
compare = ["sim_low"]

[[tests]]
name = "big"
kind = "performance"
parameter = "mean"
signal = "v.big"
segment_s = [5.0, 15.0]

[[tests]]
name = "lagged"
kind = "time"
signal = "v.lagged"
segment_s = [10.0, 30.0]
unit = "m/s"
align = { method = "none", max_lag_s = 0.5 }
compare = ["sim_low"]

[[tests]]
name = "offset"
kind = "time"
signal = "v.offset"
segment_s = [10.0, 30.0]
unit = "m/s"
"""


def _eta(e, eps):
    return 0.75 * eps / math.hypot(0.75 * eps, e)


def test_tests_are_ranked_weakest_first_with_data_derived_reasons(logs):
    plan_path = logs / "plan.toml"
    plan_path.write_text(PLAN)
    assessment = assess(load_plan(plan_path))
    ranked = weakest.rank(assessment)
    etas = [w.eta for w in ranked]
    assert etas == sorted(etas)
    # Closed forms: mean 11 vs 10 with ε_p = 0.5 → η = 0.35; a 0.1 s lag of a unit sine at
    # 0.5 Hz → e_t = 2 sin(π·0.5·0.1)/sqrt(2) = 0.2212 with ε_t = 0.1.
    # Closed forms: a 0.1 s lag of a unit sine at 0.5 Hz → e_t = sqrt(2)·sin(π·0.5·0.1) with
    # ε_t = 0.05·2; mean 11 vs 10 with ε_p = 0.5; mean 10.2 vs 10; an offset of 0.03.
    e_lag = math.sqrt(2) * math.sin(math.pi * 0.5 * 0.1)
    expected = {
        "lagged": _eta(e_lag, 0.1),
        "big": _eta(1.0, 0.5),
        "level": _eta(0.2, 0.5),
        "offset": _eta(0.03, 0.1),
    }
    assert [w.test for w in ranked] == list(expected)
    assert etas == pytest.approx(list(expected.values()), rel=1e-3)
    assert [w.below_pass_mark for w in ranked] == [True, True, False, False]
    by_name = {w.test: w for w in ranked}

    big = by_name["big"].findings[0]
    assert big.diagnosis.relative_error_pct == pytest.approx(10.0)
    assert "10.0 % above against ε_p = 5.0 %" in big.why
    level_low = by_name["level"].findings[1]
    assert level_low.role == "sim_low"
    assert "10.0 % below" in level_low.why

    lagged, lagged_low = by_name["lagged"].findings
    assert lagged.diagnosis.u_c == pytest.approx(1.0, abs=1e-3)
    assert lagged.diagnosis.dominant == "covariance"
    assert lagged.diagnosis.residual_lag_s == pytest.approx(0.1, abs=2e-3)
    assert lagged_low.diagnosis.residual_lag_s == pytest.approx(0.2, abs=2e-3)
    assert "residual lag +0.100 s (sim late)" in lagged.why
    offset = by_name["offset"].findings[0]
    assert offset.diagnosis.u_m == pytest.approx(1.0, abs=1e-9)
    assert offset.diagnosis.mean_offset == pytest.approx(0.03, abs=1e-9)
    assert "mostly an offset" in offset.why


def test_report_carries_the_weakest_block_and_page(logs):
    plan_path = logs / "plan.toml"
    plan_path.write_text(PLAN)
    assessment = assess(load_plan(plan_path))
    block = json.loads(json.dumps(to_dict(assessment)))["weakest"]
    assert [entry["test"] for entry in block] == ["lagged", "big", "level", "offset"]
    assert [entry["below_pass_mark"] for entry in block] == [True, True, False, False]
    assert block[0]["findings"][0]["diagnosis"]["u_c"] == pytest.approx(1.0, abs=1e-3)
    assert block[0]["findings"][0]["why"].startswith("Theil U_M 0.00")
    page = render_html(assessment)
    assert "Where the model is weakest" in page
    assert page.index("residual lag +0.100 s") < page.index("<h2>Tests</h2>")
