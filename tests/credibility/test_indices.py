"""The paper's equations against closed-form values written out by hand."""

import math

import numpy as np
import pytest

from credibility import indices
from credibility.errors import CredibilityError


@pytest.mark.parametrize(
    ("pass_mark", "k_e"),
    [(0.6, 0.75), (0.8, 0.8 / 0.6), (0.5, 0.5 / math.sqrt(0.75))],
)
def test_pass_mark_gain_eq_passingline(pass_mark, k_e):
    assert indices.pass_mark_gain(pass_mark) == pytest.approx(k_e, rel=1e-12)


@pytest.mark.parametrize("pass_mark", [0.6, 0.75, 0.9])
def test_error_equal_to_threshold_scores_the_pass_mark(pass_mark):
    assert indices.normalized_index(0.37, 0.37, pass_mark) == pytest.approx(pass_mark, rel=1e-12)


@pytest.mark.parametrize(
    ("ratio", "eta"),
    [
        (0.0, 1.0),
        (0.5, 0.75 / math.sqrt(0.75**2 + 0.25)),  # e = ε/2
        (2.0, 0.75 / math.sqrt(0.75**2 + 4.0)),  # e = 2ε
        (10.0, 0.75 / math.sqrt(0.75**2 + 100.0)),
    ],
)
def test_normalized_index_of_a_known_error_ratio(ratio, eta):
    assert indices.normalized_index(ratio * 3.0, 3.0) == pytest.approx(eta, rel=1e-12)


@pytest.mark.parametrize(("error", "threshold"), [(-1.0, 1.0), (1.0, 0.0), (np.nan, 1.0)])
def test_normalized_index_rejects_bad_values(error, threshold):
    with pytest.raises(CredibilityError):
        indices.normalized_index(error, threshold)


def test_performance_threshold_and_its_fallback():
    assert indices.performance_threshold(-2.0, 1.0, 0.05) == pytest.approx(0.1)
    assert indices.performance_threshold(0.0, 4.0, 0.05) == pytest.approx(0.2)
    with pytest.raises(CredibilityError, match=r"p_e = p_s = 0"):
        indices.performance_threshold(0.0, 0.0, 0.05)


def test_time_error_and_threshold_on_a_constant_offset():
    t = np.linspace(0.0, 1.0, 1001)
    y_e = np.sin(2 * np.pi * t)  # range exactly 2
    y_s = y_e + 0.03
    assert indices.rms_error(y_e, y_s) == pytest.approx(0.03, rel=1e-12)
    assert indices.range_threshold(y_e, 0.05) == pytest.approx(0.1, rel=1e-9)


def test_coherence_weights_paper_and_cifer():
    assert indices.coherence_weight(1.0) == pytest.approx(1.0)
    assert indices.coherence_weight(0.0) == pytest.approx(0.0)
    # Tischler & Remple: W_γ = [1.58 (1 − e^{−γ²})]²; 1.58 is 1/(1 − e^{−1}) to 3 digits.
    gamma2 = np.array([0.3, 0.6, 0.9])
    cifer = (1.58 * (1 - np.exp(-gamma2))) ** 2
    # (1.58198 / 1.58)² − 1 = 0.25 %: the textbook constant is rounded to three digits.
    np.testing.assert_allclose(indices.cifer_coherence_weight(gamma2), cifer, rtol=3e-3)


def test_weighted_errors_frequency_index_and_aggregates():
    assert indices.weighted_rms_error([1.0, 2.0], [0.0, 0.0], [1.0, 0.5]) == pytest.approx(1.0)
    assert indices.frequency_index(0.6, 0.8) == pytest.approx(math.sqrt(0.5))
    assert indices.rms_aggregate([0.6, 0.8]) == pytest.approx(math.sqrt(0.5))
    means = {"performance": 0.9, "time": 0.8, "frequency": 0.7}
    weights = {"performance": 0.3, "time": 0.3, "frequency": 0.4}
    expected = math.sqrt(0.3 * 0.81 + 0.3 * 0.64 + 0.4 * 0.49)
    assert indices.overall_index(means, weights) == pytest.approx(expected, rel=1e-12)
    assert indices.minimum_index([0.9, 0.75, 0.8]) == 0.75


def test_weights_must_sum_to_one():
    message = "weights: weights must sum to 1, got performance 0.3 + time 0.3 + frequency 0.3 = 0.9"
    with pytest.raises(CredibilityError) as info:
        indices.check_weights({"performance": 0.3, "time": 0.3, "frequency": 0.3})
    assert str(info.value) == message


def test_theil_inequality_coefficient():
    y = np.array([1.0, -1.0, 1.0, -1.0])
    assert indices.theil_inequality(y, y) == 0.0
    assert indices.theil_inequality(y, -y) == pytest.approx(1.0)  # RMS 2 / (1 + 1)
    assert indices.theil_inequality(y, 0.5 * y) == pytest.approx(0.5 / 1.5)


def test_cifer_cost_of_a_known_mismatch():
    # 1 dB and 10° everywhere at γ² = 1: J = 20 · W_γ(1)² · (1 + 0.01745 · 100).
    n = 20
    j = indices.cifer_cost(np.ones(n), np.zeros(n), np.full(n, 10.0), np.zeros(n), np.ones(n))
    assert j == pytest.approx(20.0 * (1.0 + 0.01745 * 100.0), rel=1e-12)
