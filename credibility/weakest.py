"""Where the model is weakest: every test ranked by its index, each with the reason its own
numbers give.

η says *how far* a simulation is from the flight; a model developer also needs *what kind*
of error it is. For a time test that is Theil's split of the mean squared error (offset,
amplitude or unsystematic) and the lag left between the curves; for a frequency test, the
band where the magnitude and phase errors peak; for a performance test, by how much the sim
is above or below the flight against the allowed ε_p. Nothing here is canned text: every
sentence is built from numbers the assessment already holds.
"""

from dataclasses import dataclass

import numpy as np

from credibility import indices, signals
from credibility.assess import (
    Assessment,
    FrequencyResult,
    FrequencyRow,
    PerformanceResult,
    PerformanceRow,
    Result,
    TimeResult,
    TimeRow,
)

#: A Theil share above this names the error's kind; below it the error is called mixed.
DOMINANT_SHARE = 0.5
#: The worst band is the run of coherent grid points around the peak where the weighted
#: error stays at or above this fraction of the peak (the half-maximum width).
BAND_FRACTION = 0.5

_THEIL_KINDS = {
    "bias": "an offset",
    "variance": "an amplitude (scale) error",
    "covariance": "unsystematic (noise, lag or a different shape)",
}


@dataclass(frozen=True)
class TimeDiagnosis:
    """Theil's proportions of e_t² and the lag between the curves as scored.

    ``residual_lag_s`` > 0 means the sim's curve is late; it is searched within ±max_lag_s
    (at most a quarter of the segment) on the scored curves, after any alignment the plan
    applied (``alignment_shift_s``). ``None`` where undefined (identical or flat curves).
    """

    u_m: float | None
    u_s: float | None
    u_c: float | None
    mean_offset: float
    sigma_ratio: float | None
    alignment_method: str
    alignment_shift_s: float
    residual_lag_s: float | None
    unit: str

    @property
    def dominant(self) -> str | None:
        """``bias``, ``variance``, ``covariance`` or None when no share dominates."""
        if self.u_m is None or self.u_s is None or self.u_c is None:
            return None
        shares = {"bias": self.u_m, "variance": self.u_s, "covariance": self.u_c}
        kind = max(shares, key=lambda k: shares[k])
        return kind if shares[kind] > DOMINANT_SHARE else None

    def why(self) -> str:
        if self.u_m is None:
            return "the curves are identical: no error to explain"
        kind = _THEIL_KINDS[self.dominant] if self.dominant else "mixed (no share above 50 %)"
        parts = [
            f"Theil U_M {self.u_m:.2f} / U_S {self.u_s:.2f} / U_C {self.u_c:.2f}: mostly {kind}",
            f"sim mean {self.mean_offset:+.3g} {self.unit}".rstrip(),
        ]
        if self.sigma_ratio is not None:
            parts.append(f"sim σ {100.0 * (self.sigma_ratio - 1.0):+.1f} %")
        if self.alignment_method != "none":
            parts.append(
                f"aligned by {self.alignment_method}, shift {self.alignment_shift_s:+.3f} s"
            )
        if self.residual_lag_s is not None:
            late = "late" if self.residual_lag_s > 0 else "early"
            parts.append(f"residual lag {self.residual_lag_s:+.3f} s (sim {late})")
        return "; ".join(parts)


@dataclass(frozen=True)
class WorstBand:
    """Where on the coherent grid one error (magnitude in dB or phase in degrees) peaks.

    ``error`` is sim − real at ``freq_hz`` (a negative phase error: the sim lags); the band
    is the contiguous run of coherent points around it whose W_γ-weighted error is at least
    half the peak's, the width that matters for η.
    """

    freq_hz: float
    band_hz: tuple[float, float]
    error: float


@dataclass(frozen=True)
class FrequencyDiagnosis:
    magnitude: WorstBand
    phase: WorstBand
    mag_error_ratio: float
    phase_error_ratio: float
    excluded_hz: tuple[float, ...]
    n_points: int
    cifer_j: float

    def why(self) -> str:
        if self.mag_error_ratio == 0.0 and self.phase_error_ratio == 0.0:
            return "the responses are identical on the coherent grid: no error to explain"
        mag, pha = self.magnitude, self.phase
        lead = "lags" if pha.error < 0 else "leads"
        worse = "phase" if self.phase_error_ratio > self.mag_error_ratio else "magnitude"
        excluded = (
            f"{len(self.excluded_hz)} of {self.n_points} frequencies excluded (γ² < ε_co): "
            + ", ".join(f"{f:.3g}" for f in self.excluded_hz)
            + " Hz"
            if self.excluded_hz
            else "no frequency excluded"
        )
        return (
            f"magnitude worst at {mag.freq_hz:.3g} Hz (sim {mag.error:+.2f} dB; band "
            f"{_band(mag.band_hz)}); phase worst at {pha.freq_hz:.3g} Hz (sim {lead} by "
            f"{abs(pha.error):.1f}°; band {_band(pha.band_hz)}); e/ε magnitude "
            f"{self.mag_error_ratio:.2f}, phase {self.phase_error_ratio:.2f}: {worse} dominates; "
            f"{excluded}; CIFER J {self.cifer_j:.1f}"
        )


@dataclass(frozen=True)
class PerformanceDiagnosis:
    parameter: str
    unit: str
    p_e: float
    p_s: float
    threshold: float

    @property
    def relative_error_pct(self) -> float | None:
        """(p_s − p_e) / |p_e| in percent; None when p_e = 0."""
        return None if self.p_e == 0.0 else 100.0 * (self.p_s - self.p_e) / abs(self.p_e)

    @property
    def threshold_pct(self) -> float | None:
        """ε_p as a percentage of |p_e|; None when p_e = 0."""
        return None if self.p_e == 0.0 else 100.0 * self.threshold / abs(self.p_e)

    def why(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        values = f"sim {self.parameter} {self.p_s:.4g}{unit} vs real {self.p_e:.4g}{unit}"
        ratio = abs(self.p_s - self.p_e) / self.threshold
        if self.relative_error_pct is None:
            return f"{values}; e_p/ε_p = {ratio:.2f} (ε_p = {self.threshold:.4g}{unit})"
        if self.relative_error_pct == 0.0:
            return f"{values}: equal (ε_p = {self.threshold_pct:.1f} %)"
        side = "above" if self.relative_error_pct > 0 else "below"
        return (
            f"{values}: {abs(self.relative_error_pct):.1f} % {side} against ε_p = "
            f"{self.threshold_pct:.1f} % (e_p/ε_p = {ratio:.2f})"
        )


Diagnosis = TimeDiagnosis | FrequencyDiagnosis | PerformanceDiagnosis


@dataclass(frozen=True)
class Finding:
    """One sim's diagnosis on one test."""

    role: str
    eta: float
    diagnosis: Diagnosis

    @property
    def why(self) -> str:
        return self.diagnosis.why()


@dataclass(frozen=True)
class Weakness:
    """One test on the weakest-first list: the assessed sim's η decides the rank, the
    compared sims (e.g. the low-precision model) follow with their own diagnosis."""

    test: str
    kind: str
    eta: float
    below_pass_mark: bool
    findings: tuple[Finding, ...]


def rank(assessment: Assessment) -> tuple[Weakness, ...]:
    """Every test, lowest η of the assessed sim first (plan order among equal η)."""
    pass_mark = assessment.plan.pass_mark
    weaknesses = [
        Weakness(
            test=result.test.name,
            kind=result.test.kind,
            eta=result.eta,
            below_pass_mark=result.eta < pass_mark,
            findings=_findings(result),
        )
        for result in assessment.results
    ]
    return tuple(sorted(weaknesses, key=lambda w: w.eta))


def _findings(result: Result) -> tuple[Finding, ...]:
    if isinstance(result, TimeResult):
        return tuple(Finding(r.role, r.eta, diagnose_time(result, r)) for r in result.rows)
    if isinstance(result, FrequencyResult):
        return tuple(Finding(r.role, r.eta, diagnose_frequency(result, r)) for r in result.rows)
    return tuple(Finding(r.role, r.eta, diagnose_performance(result, r)) for r in result.rows)


def diagnose_time(result: TimeResult, row: TimeRow) -> TimeDiagnosis:
    y_e, y_s = result.real_values, row.values
    shares = indices.theil_decomposition(y_e, y_s)
    u_m, u_s, u_c = shares if shares is not None else (None, None, None)
    sigma_e = float(y_e.std())
    align = result.test.align
    return TimeDiagnosis(
        u_m=u_m,
        u_s=u_s,
        u_c=u_c,
        mean_offset=float(y_s.mean() - y_e.mean()),
        sigma_ratio=float(y_s.std()) / sigma_e if sigma_e > 0.0 else None,
        alignment_method=align.method,
        alignment_shift_s=row.alignment_shift_s,
        residual_lag_s=residual_lag_s(result.grid_s, y_e, y_s, align.max_lag_s),
        unit=result.test.unit,
    )


def residual_lag_s(
    grid_s: np.ndarray, y_e: np.ndarray, y_s: np.ndarray, max_lag_s: float
) -> float | None:
    """The lag (s) of ``y_s`` behind ``y_e`` on a common grid: the peak of their normalized
    cross-correlation within ±min(max_lag_s, a quarter of the grid). None for identical or
    flat curves, where no lag is defined."""
    if np.array_equal(y_e, y_s) or np.ptp(y_e) == 0.0 or np.ptp(y_s) == 0.0:
        return None
    interval = float(grid_s[1] - grid_s[0])
    duration = float(grid_s[-1] - grid_s[0])
    lag = min(max_lag_s, duration / 4.0)
    if lag < interval:
        return None
    t = grid_s - grid_s[0]
    real = signals.Signal("real", "scored curve", t, y_e)
    sim = signals.Signal("sim", "scored curve", t, y_s)
    return signals.correlation_lag(real, sim, (lag, duration - lag), lag, lag, interval)


def diagnose_frequency(result: FrequencyResult, row: FrequencyRow) -> FrequencyDiagnosis:
    freqs = result.real.freqs_hz
    mag_error = row.estimate.magnitude_db - result.real.magnitude_db
    phase_error = row.phase_deg - row.real_phase_deg
    return FrequencyDiagnosis(
        magnitude=worst_band(freqs, mag_error, row.weight, row.included),
        phase=worst_band(freqs, phase_error, row.weight, row.included),
        mag_error_ratio=row.e_mag_db / row.eps_mag_db,
        phase_error_ratio=row.e_pha_deg / row.eps_pha_deg,
        excluded_hz=tuple(float(f) for f in row.excluded_hz),
        n_points=int(freqs.size),
        cifer_j=row.cifer_j,
    )


def worst_band(
    freqs_hz: np.ndarray, error: np.ndarray, weight: np.ndarray, included: np.ndarray
) -> WorstBand:
    """The peak of the W_γ-weighted |error| over the included grid points and its
    half-maximum run of neighbours (stopped by an excluded point)."""
    weighted = np.where(included, np.abs(weight * error), -np.inf)
    peak = int(np.argmax(weighted))
    floor = BAND_FRACTION * weighted[peak]
    low = high = peak
    while low > 0 and weighted[low - 1] >= floor:
        low -= 1
    while high < freqs_hz.size - 1 and weighted[high + 1] >= floor:
        high += 1
    return WorstBand(
        freq_hz=float(freqs_hz[peak]),
        band_hz=(float(freqs_hz[low]), float(freqs_hz[high])),
        error=float(error[peak]),
    )


def diagnose_performance(result: PerformanceResult, row: PerformanceRow) -> PerformanceDiagnosis:
    assert result.test.unit is not None  # __post_init__ fills it from the parameter
    return PerformanceDiagnosis(
        parameter=result.test.parameter,
        unit=result.test.unit,
        p_e=row.p_e,
        p_s=row.p_s,
        threshold=row.threshold,
    )


def _band(band_hz: tuple[float, float]) -> str:
    low, high = band_hz
    return f"{low:.3g} Hz" if low == high else f"{low:.3g}–{high:.3g} Hz"
