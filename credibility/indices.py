"""The normalized credibility indices of Dai, Ke, Quan and Cai, section 3, as pure functions.

Equation labels are the paper's (*Simulation Credibility Assessment Methodology with
FPGA-based Hardware-in-the-loop Platform*), e.g. eq. (NormIndex). Everything here is
arithmetic on errors and thresholds: it reads no logs and draws nothing, so the
paper's own tables can be recomputed with it (``credibility.paper``) and every number the
report shows comes from one place.
"""

from collections.abc import Mapping
from typing import Literal, get_args

import numpy as np
from numpy.typing import ArrayLike

from credibility.errors import CredibilityError

#: The paper's pass mark η_pass (section 2.3): η = 0.6 exactly when the error equals its threshold.
DEFAULT_PASS_MARK = 0.6
#: The paper's percentage coefficient K_p (eq. (thres)), "usually applicable".
DEFAULT_K_P = 0.05
#: Coherence gate ε_co (eq. (Cohe)), from Tischler & Remple p. 38 as the paper cites it.
DEFAULT_COHERENCE_MIN = 0.6
#: Threshold ε_min for η_min that the paper calls "high credibility" (eq. (worse)).
DEFAULT_ETA_MIN = 0.9

#: CIFER cost weights (Tischler & Remple, Aircraft and Rotorcraft System Identification):
#: magnitude in dB weighted 1, phase in degrees weighted 0.01745 (1 dB ≈ 7.57°). The same
#: values and the 20/n scaling appear in NASA's LoesCost.m (C. Regan, 2006).
CIFER_GAIN_WEIGHT = 1.0
CIFER_PHASE_WEIGHT = 0.01745
#: 1 / (1 − e^{-1}) ≈ 1.58: the coherence weight reaches 1 at γ² = 1.
_COHERENCE_WEIGHT_SCALE = 1.0 / (1.0 - np.exp(-1.0))

Kind = Literal["performance", "time", "frequency"]
KINDS: tuple[str, ...] = get_args(Kind)


def pass_mark_gain(pass_mark: float = DEFAULT_PASS_MARK) -> float:
    """K_e of eq. (passingline): the scale that puts η = pass_mark at e = ε (0.6 → 0.75)."""
    if not 0.0 < pass_mark < 1.0:
        raise CredibilityError(f"pass mark must lie in (0, 1), got {pass_mark!r}")
    return pass_mark / np.sqrt(1.0 - pass_mark**2)


def normalized_index(error: float, threshold: float, pass_mark: float = DEFAULT_PASS_MARK) -> float:
    """η = f_norm(e, ε) of eq. (NormIndex): maps an error in [0, ∞) to an index in (0, 1]."""
    if not np.isfinite(error) or error < 0.0:
        raise CredibilityError(f"error must be a finite number ≥ 0, got {error!r}")
    if not np.isfinite(threshold) or threshold <= 0.0:
        raise CredibilityError(f"error threshold must be a finite number > 0, got {threshold!r}")
    scaled = pass_mark_gain(pass_mark) * threshold
    return float(scaled / np.hypot(scaled, error))


def performance_error(p_e: float, p_s: float) -> float:
    """e_p = |p_e − p_s| of eq. (Ekey)."""
    return abs(p_e - p_s)


def performance_threshold(p_e: float, p_s: float, k_p: float = DEFAULT_K_P) -> float:
    """ε_p = K_p·|p_e| of eq. (thres), with the paper's fallback K_p·|p_s| when p_e = 0."""
    if k_p <= 0.0:
        raise CredibilityError(f"K_p must be > 0, got {k_p!r}")
    if p_e != 0.0:
        return k_p * abs(p_e)
    if p_s != 0.0:
        return k_p * abs(p_s)
    raise CredibilityError(
        "performance threshold undefined: p_e = p_s = 0, so eq. (thres) and its fallback "
        "K_p·|p_s| are both 0; give the test an explicit 'threshold'"
    )


def rms_error(y_e: ArrayLike, y_s: ArrayLike) -> float:
    """e_t of eq. (RQ): RMS difference of two curves sampled on the same n_t points."""
    diff = np.asarray(y_e, dtype=float) - np.asarray(y_s, dtype=float)
    return float(np.sqrt(np.mean(diff**2)))


def range_threshold(y_e: ArrayLike, k_p: float = DEFAULT_K_P) -> float:
    """K_p × max_{i,j}|y_e(i) − y_e(j)| of eqs. (EtThre), (EmagPha), (EmagPha1).

    The maximum pairwise difference of a sampled curve is its range, max − min.
    """
    values = np.asarray(y_e, dtype=float)
    return float(k_p * (values.max() - values.min()))


def coherence_weight(gamma2: ArrayLike) -> np.ndarray:
    """W_γ of the paper (section 3.3.2): (1 − e^{−γ²}) / (1 − e^{−1}), 1 at γ² = 1.

    γ² is the magnitude-squared coherence, the paper's η_co of eq. (bbb).
    """
    return _COHERENCE_WEIGHT_SCALE * (1.0 - np.exp(-np.asarray(gamma2, dtype=float)))


def cifer_coherence_weight(gamma2: ArrayLike) -> np.ndarray:
    """Tischler & Remple's W_γ = [1.58 (1 − e^{−γ²})]², the square of the paper's W_γ."""
    return coherence_weight(gamma2) ** 2


def weighted_rms_error(a: ArrayLike, b: ArrayLike, weight: ArrayLike) -> float:
    """e_mag / e_pha of eqs. (emag), (Epha): sqrt(mean(W_γ² (a − b)²)) with the paper's W_γ."""
    diff = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    w = np.asarray(weight, dtype=float)
    return float(np.sqrt(np.mean((w * diff) ** 2)))


def frequency_index(eta_mag: float, eta_pha: float) -> float:
    """η_f of eq. (freqIndex): the RMS of η_mag and η_pha."""
    return float(np.sqrt(0.5 * (eta_mag**2 + eta_pha**2)))


def rms_aggregate(etas: ArrayLike) -> float:
    """η̄_p, η̄_t or η̄_f of eq. (aveP): the RMS of the per-test indices of one kind."""
    values = np.asarray(etas, dtype=float)
    if values.size == 0:
        raise CredibilityError("cannot aggregate an empty list of indices (eq. (aveP))")
    return float(np.sqrt(np.mean(values**2)))


def check_weights(weights: Mapping[str, float], source: str = "weights") -> None:
    """The α of eq. (overall): each in [0, 1], one per known kind, summing to 1."""
    for kind, alpha in weights.items():
        if kind not in KINDS:
            raise CredibilityError(f"{source}: unknown kind {kind!r}; expected one of {KINDS}")
        if not 0.0 <= alpha <= 1.0:
            raise CredibilityError(f"{source}: weight {kind} = {alpha!r} is outside [0, 1]")
    total = sum(weights.values())
    if abs(total - 1.0) > 1e-9:
        parts = " + ".join(f"{k} {v:g}" for k, v in weights.items())
        raise CredibilityError(f"{source}: weights must sum to 1, got {parts} = {total:.6g}")


def overall_index(means: Mapping[str, float], weights: Mapping[str, float]) -> float:
    """η_all of eq. (overall): sqrt(Σ α_k η̄_k²) over the kinds, the α summing to 1."""
    check_weights(weights)
    missing = [kind for kind, alpha in weights.items() if alpha > 0.0 and kind not in means]
    if missing:
        raise CredibilityError(f"weights: kinds {missing} have a weight but no index")
    return float(np.sqrt(sum(alpha * means[kind] ** 2 for kind, alpha in weights.items() if alpha)))


def minimum_index(etas: ArrayLike) -> float:
    """η_min of eq. (worse): the worst per-test index of every kind."""
    values = np.asarray(etas, dtype=float)
    if values.size == 0:
        raise CredibilityError("cannot take η_min of an empty list of indices (eq. (worse))")
    return float(values.min())


def theil_inequality(y_e: ArrayLike, y_s: ArrayLike) -> float:
    """Theil's inequality coefficient U = RMS(y_s − y_e) / (RMS(y_s) + RMS(y_e)), in [0, 1].

    The classical time-domain validation metric (0 is a perfect match, 1 the worst), shown
    beside η_t so a reviewer can compare the two.
    """
    e = np.asarray(y_e, dtype=float)
    s = np.asarray(y_s, dtype=float)
    denominator = np.sqrt(np.mean(s**2)) + np.sqrt(np.mean(e**2))
    if denominator == 0.0:
        raise CredibilityError("Theil's coefficient undefined: both curves are identically zero")
    return rms_error(e, s) / float(denominator)


def cifer_cost(
    mag_e_db: ArrayLike,
    mag_s_db: ArrayLike,
    phase_e_deg: ArrayLike,
    phase_s_deg: ArrayLike,
    gamma2: ArrayLike,
) -> float:
    """CIFER's frequency-response cost J (Tischler & Remple), with their W_γ.

    J = (20/n) Σ W_γ [W_g (|T_e| − |T_s|)² + W_p (∠T_e − ∠T_s)²], magnitude in dB, phase in
    degrees, W_g = 1, W_p = 0.01745, W_γ = [1.58 (1 − e^{−γ²})]². J ≤ 100 is the usual
    "acceptable" guideline for a model fit, J ≤ 50 a good one.
    """
    dmag = np.asarray(mag_e_db, dtype=float) - np.asarray(mag_s_db, dtype=float)
    dpha = np.asarray(phase_e_deg, dtype=float) - np.asarray(phase_s_deg, dtype=float)
    w_gamma = cifer_coherence_weight(gamma2)
    terms = w_gamma * (CIFER_GAIN_WEIGHT * dmag**2 + CIFER_PHASE_WEIGHT * dpha**2)
    return float(20.0 / dmag.size * terms.sum())


def theil_decomposition(y_e: ArrayLike, y_s: ArrayLike) -> tuple[float, float, float] | None:
    """Theil's proportions (U_M, U_S, U_C) of the mean squared error, summing to 1.

    Theil (1966, *Applied Economic Forecasting*, ch. 2) splits
    MSE = (ȳ_s − ȳ_e)² + (σ_s − σ_e)² + 2 (1 − r) σ_s σ_e (population σ, correlation r):
    U_M, the bias share, says the error is an offset; U_S, the variance share, an amplitude
    or scale error; U_C, the covariance share, unsystematic (noise, a lag, a different
    shape). ``None`` when the curves are identical: there is no error to split.
    """
    e = np.asarray(y_e, dtype=float)
    s = np.asarray(y_s, dtype=float)
    mse = float(np.mean((s - e) ** 2))
    if mse == 0.0:
        return None
    sigma_e, sigma_s = float(e.std()), float(s.std())
    bias = (float(s.mean()) - float(e.mean())) ** 2
    variance = (sigma_s - sigma_e) ** 2
    # σ_s σ_e r is the covariance; with a constant curve it is 0 and so is this share.
    covariance = 2.0 * (sigma_s * sigma_e - float(np.mean((s - s.mean()) * (e - e.mean()))))
    # The three terms sum to the MSE in exact arithmetic; dividing by their sum keeps the
    # shares summing to 1 when rounding leaves a tiny negative covariance term.
    covariance = max(covariance, 0.0)
    total = bias + variance + covariance
    return bias / total, variance / total, covariance / total
