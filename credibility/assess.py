"""Running a plan: logs in, per-test indices and the paper's aggregates out.

This is the compute half; ``credibility.report`` renders what it returns. Every number the
method used (thresholds and their rule, n_t, grids, windows, excluded frequencies, lags,
smoothing) is kept in the result objects so the report can show it.
"""

import datetime as dt
import importlib.metadata
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from credibility import indices, signals, spectral
from credibility.errors import CredibilityError
from credibility.logs import LogFile, SignalSpec, open_log
from credibility.plan import FrequencyTest, PerformanceTest, Plan, Test, TimeTest


@dataclass(frozen=True)
class PerformanceRow:
    """One sim against the real log on one parameter (a row of the paper's Table 1)."""

    role: str
    p_e: float
    p_s: float
    error: float
    threshold: float
    threshold_rule: str
    eta: float


@dataclass(frozen=True)
class PerformanceResult:
    test: PerformanceTest
    rows: tuple[PerformanceRow, ...]

    @property
    def eta(self) -> float:
        return self.rows[0].eta


@dataclass(frozen=True, eq=False)
class TimeRow:
    """One sim curve against the real one (a row of the paper's Table 2)."""

    role: str
    values: np.ndarray
    segment_s: tuple[float, float]
    alignment_shift_s: float
    error: float
    eta: float
    theil_u: float


@dataclass(frozen=True, eq=False)
class TimeResult:
    test: TimeTest
    #: Time since t_a of the common grid t_1 … t_{n_t}.
    grid_s: np.ndarray
    real_values: np.ndarray
    threshold: float
    threshold_rule: str
    rows: tuple[TimeRow, ...]
    zero_output_error: float
    zero_output_eta: float

    @property
    def eta(self) -> float:
        return self.rows[0].eta

    @property
    def n_t(self) -> int:
        return self.grid_s.size


@dataclass(frozen=True, eq=False)
class FrequencyRow:
    """One sim response against the real one on the coherent part of the grid."""

    role: str
    estimate: spectral.FrequencyResponseEstimate
    real_phase_deg: np.ndarray
    phase_deg: np.ndarray
    included: np.ndarray
    weight: np.ndarray
    e_mag_db: float
    e_pha_deg: float
    eps_mag_db: float
    eps_pha_deg: float
    threshold_rule: str
    eta_mag: float
    eta_pha: float
    eta: float
    cifer_j: float

    @property
    def excluded_hz(self) -> np.ndarray:
        return self.estimate.freqs_hz[~self.included]


@dataclass(frozen=True, eq=False)
class FrequencyResult:
    test: FrequencyTest
    real: spectral.FrequencyResponseEstimate
    sample_rate_hz: float
    rows: tuple[FrequencyRow, ...]

    @property
    def eta(self) -> float:
        return self.rows[0].eta


Result = PerformanceResult | TimeResult | FrequencyResult


@dataclass(frozen=True)
class LogInfo:
    """Provenance of one input log."""

    role: str
    path: Path
    sha256: str
    format: str
    warnings: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class Assessment:
    """The whole answer: per-test results, eq. (aveP) means, η_all, η_min and the verdicts."""

    plan: Plan
    logs: tuple[LogInfo, ...]
    results: tuple[Result, ...]
    means: dict[str, float]
    eta_all: float
    eta_min: float
    package_version: str
    created_utc: str

    @property
    def meets_eps_min(self) -> bool:
        """η_min ≥ ε_min: the paper's condition for η_all to be meaningful (eq. (worse))."""
        return self.eta_min >= self.plan.eps_min

    @property
    def passes(self) -> bool:
        """η_all at or above the pass mark."""
        return self.eta_all >= self.plan.pass_mark


def package_version() -> str:
    return importlib.metadata.version("hil-rig")


def steps(plan: Plan) -> int:
    """How many progress steps ``assess`` reports: one per distinct log, one per test."""
    return len(set(plan.logs.values())) + len(plan.tests)


def assess(plan: Plan, progress: Callable[[str], None] = lambda _: None) -> Assessment:
    """Score every test of ``plan``; ``progress`` is called once per step with its label."""
    opened: dict[Path, LogFile] = {}
    for path in dict.fromkeys(plan.logs.values()):
        progress(f"reading {path.name}")
        opened[path] = open_log(path)
    logs = {role: opened[path] for role, path in plan.logs.items()}
    results = []
    for test in plan.tests:
        progress(f"{test.kind} test {test.name}")
        results.append(_run(test, logs, plan))
    means = {
        kind: indices.rms_aggregate([r.eta for r in results if r.test.kind == kind])
        for kind in indices.KINDS
        if any(r.test.kind == kind for r in results)
    }
    return Assessment(
        plan=plan,
        logs=tuple(
            LogInfo(role, log.path, log.sha256, log.format, log.warnings)
            for role, log in logs.items()
        ),
        results=tuple(results),
        means=means,
        eta_all=indices.overall_index(means, plan.weights),
        eta_min=indices.minimum_index([r.eta for r in results]),
        package_version=package_version(),
        created_utc=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
    )


def _run(test: Test, logs: dict[str, LogFile], plan: Plan) -> Result:
    try:
        if isinstance(test, PerformanceTest):
            return _performance(test, logs, plan)
        if isinstance(test, TimeTest):
            return _time(test, logs, plan)
        return _frequency(test, logs, plan)
    except CredibilityError as exc:
        raise CredibilityError(f"test {test.name!r}: {exc}") from None


def _windowed(log: LogFile, spec: SignalSpec, segment_s, plan: Plan) -> signals.Signal:
    return signals.window(log.signal(spec), segment_s, plan.max_gap_s, spec.drop_nan)


# --- performance ---------------------------------------------------------------------------


def _parameter(test: PerformanceTest, sig: signals.Signal) -> float:
    values = sig.values
    if test.highpass_hz is not None:
        values = signals.highpass(values, sig.median_interval_s(), test.highpass_hz)
    if test.parameter == "mean":
        return float(values.mean())
    if test.parameter == "std":
        return float(values.std(ddof=1))
    metrics = signals.step_metrics(sig.time_s, values, test.settling_band, test.steady_window_s)
    return {
        "overshoot": metrics.overshoot_pct,
        "rise_time": metrics.rise_time_s,
        "settling_time": metrics.settling_time_s,
        "steady_state": metrics.steady_state,
    }[test.parameter]


def _performance(test: PerformanceTest, logs: dict[str, LogFile], plan: Plan) -> PerformanceResult:
    if test.parameter == "value":
        p_e = test.values[test.roles.real]
        sims = {role: test.values[role] for role in test.roles.sims}
    else:
        real = _windowed(logs[test.roles.real], test.signal, test.segment_s, plan)
        p_e = _parameter(test, real)
        sims = {
            role: _parameter(test, _windowed(logs[role], test.signal_sim, test.segment_sim_s, plan))
            for role in test.roles.sims
        }
    rows = []
    for role, p_s in sims.items():
        if test.threshold is not None:
            threshold, rule = test.threshold, "plan"
        else:
            threshold = indices.performance_threshold(p_e, p_s, test.k_p)
            rule = "K_p·|p_e|" if p_e != 0.0 else "K_p·|p_s| (p_e = 0)"
        error = indices.performance_error(p_e, p_s)
        eta = indices.normalized_index(error, threshold, plan.pass_mark)
        rows.append(PerformanceRow(role, p_e, p_s, error, threshold, rule, eta))
    return PerformanceResult(test, tuple(rows))


# --- time ----------------------------------------------------------------------------------


def _alignment_shift(test: TimeTest, real_log: LogFile, sim_log: LogFile) -> float:
    """Seconds to add to the sim segment so its curve lines up with the real one."""
    align = test.align
    if align.method == "none":
        return 0.0
    real = real_log.signal(align.signal)
    sim = sim_log.signal(align.signal_sim)
    (t_a, t_b), (s_a, s_b) = test.segment_s, test.segment_sim_s
    lag = align.max_lag_s
    if align.method == "event":
        level, direction = align.threshold, align.direction
        t_real = signals.first_crossing(real, level, direction, (t_a - lag, t_b + lag))
        t_sim = signals.first_crossing(sim, level, direction, (s_a - lag, s_b + lag))
        return (t_sim - s_a) - (t_real - t_a)
    return signals.correlation_lag(real, sim, test.segment_s, s_a, lag, real.median_interval_s())


def _time(test: TimeTest, logs: dict[str, LogFile], plan: Plan) -> TimeResult:
    real_log = logs[test.roles.real]
    real = _windowed(real_log, test.signal, test.segment_s, plan)
    duration = test.segment_s[1] - test.segment_s[0]
    n_t = test.n_t or round(duration / real.median_interval_s()) + 1
    grid = np.linspace(0.0, duration, n_t)
    interval = grid[1] - grid[0]

    def curve(sig: signals.Signal, start: float) -> np.ndarray:
        values = signals.resample(sig, start + grid)
        if test.smoothing is None:
            return values
        return signals.smooth(values, interval, test.smoothing.window_s, test.smoothing.polyorder)

    y_e = curve(real, test.segment_s[0])
    if test.threshold is not None:
        threshold, rule = test.threshold, "plan"
    else:
        threshold, rule = indices.range_threshold(y_e, test.k_p), "K_p·(max y_e − min y_e)"
    rows = []
    for role in test.roles.sims:
        shift = _alignment_shift(test, real_log, logs[role])
        segment = (test.segment_sim_s[0] + shift, test.segment_sim_s[1] + shift)
        y_s = curve(_windowed(logs[role], test.signal_sim, segment, plan), segment[0])
        error = indices.rms_error(y_e, y_s)
        rows.append(
            TimeRow(
                role=role,
                values=y_s,
                segment_s=segment,
                alignment_shift_s=shift,
                error=error,
                eta=indices.normalized_index(error, threshold, plan.pass_mark),
                theil_u=indices.theil_inequality(y_e, y_s),
            )
        )
    zero_error = indices.rms_error(y_e, np.zeros_like(y_e))
    return TimeResult(
        test=test,
        grid_s=grid,
        real_values=y_e,
        threshold=threshold,
        threshold_rule=rule,
        rows=tuple(rows),
        zero_output_error=zero_error,
        zero_output_eta=indices.normalized_index(zero_error, threshold, plan.pass_mark),
    )


# --- frequency -----------------------------------------------------------------------------


def _uniform_pair(
    log: LogFile, input_spec: SignalSpec, output_spec: SignalSpec, segment_s, rate_hz, plan
) -> tuple[np.ndarray, np.ndarray]:
    """Input and output on one uniform grid (spectra need uniform samples)."""
    x = _windowed(log, input_spec, segment_s, plan)
    y = _windowed(log, output_spec, segment_s, plan)
    grid = np.arange(segment_s[0], segment_s[1], 1.0 / rate_hz)
    return signals.resample(x, grid), signals.resample(y, grid)


def _frequency(test: FrequencyTest, logs: dict[str, LogFile], plan: Plan) -> FrequencyResult:
    real_log = logs[test.roles.real]
    rate_hz = (
        test.sample_rate_hz
        or 1.0 / _windowed(real_log, test.output, test.segment_s, plan).median_interval_s()
    )
    freqs = spectral.log_grid(test.band_hz, test.n_points)
    shortest_s = min(
        test.segment_s[1] - test.segment_s[0], test.segment_sim_s[1] - test.segment_sim_s[0]
    )
    windows = test.windows_s or spectral.default_windows(shortest_s, test.band_hz)

    def estimate(log: LogFile, input_spec, output_spec, segment_s):
        x, y = _uniform_pair(log, input_spec, output_spec, segment_s, rate_hz, plan)
        return spectral.estimate_response(x, y, rate_hz, freqs, windows, test.overlap)

    real = estimate(real_log, test.input, test.output, test.segment_s)
    rows = []
    for role in test.roles.sims:
        sim = estimate(logs[role], test.input_sim, test.output_sim, test.segment_sim_s)
        rows.append(_compare_responses(test, real, sim, role, plan.pass_mark))
    return FrequencyResult(test, real, rate_hz, tuple(rows))


def _compare_responses(
    test: FrequencyTest,
    real: spectral.FrequencyResponseEstimate,
    sim: spectral.FrequencyResponseEstimate,
    role: str,
    pass_mark: float,
) -> FrequencyRow:
    """Eqs. (Cohe), (emag), (Epha), (EmagPha), (MatFre), (freqIndex) and CIFER's J.

    A grid point counts only where both responses are coherent (γ² ≥ ε_co); W_γ uses the
    lower of the two coherences, so neither curve's noise is trusted more than the other's.
    """
    gamma2 = np.minimum(real.coherence, sim.coherence)
    included = gamma2 >= test.coherence_min
    if included.sum() < 2:
        raise CredibilityError(
            f"sim {role!r}: only {int(included.sum())} of {included.size} frequencies have "
            f"coherence ≥ {test.coherence_min:g} in both logs (eq. (Cohe))"
        )
    weight = indices.coherence_weight(gamma2) if test.coherence_weighting else np.ones_like(gamma2)
    real_phase, sim_phase = spectral.phase_pair_deg(real.complex_response, sim.complex_response)
    m_e, m_s = real.magnitude_db[included], sim.magnitude_db[included]
    p_e, p_s = real_phase[included], sim_phase[included]
    w = weight[included]
    e_mag = indices.weighted_rms_error(m_e, m_s, w)
    e_pha = indices.weighted_rms_error(p_e, p_s, w)
    eps_mag = test.threshold_mag_db or indices.range_threshold(m_e, test.k_p)
    eps_pha = test.threshold_phase_deg or indices.range_threshold(p_e, test.k_p)
    rule = ", ".join(
        f"{name}: {'plan' if given else 'K_p·range of the real curve over the coherent grid'}"
        for name, given in (("ε_mag", test.threshold_mag_db), ("ε_pha", test.threshold_phase_deg))
    )
    eta_mag = indices.normalized_index(e_mag, eps_mag, pass_mark)
    eta_pha = indices.normalized_index(e_pha, eps_pha, pass_mark)
    return FrequencyRow(
        role=role,
        estimate=sim,
        real_phase_deg=real_phase,
        phase_deg=sim_phase,
        included=included,
        weight=weight,
        e_mag_db=e_mag,
        e_pha_deg=e_pha,
        eps_mag_db=eps_mag,
        eps_pha_deg=eps_pha,
        threshold_rule=rule,
        eta_mag=eta_mag,
        eta_pha=eta_pha,
        eta=indices.frequency_index(eta_mag, eta_pha),
        cifer_j=indices.cifer_cost(m_e, m_s, p_e, p_s, gamma2[included]),
    )
