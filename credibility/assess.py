"""Running a plan: logs in, per-test indices and the paper's aggregates out.

This is the compute half; ``credibility.report`` renders what it returns. Every number the
method used (thresholds and their rule, n_t, grids, windows, excluded frequencies, lags,
smoothing) is kept in the result objects so the report can show it. A test the logs cannot
score is kept too, as ``NotScored`` with its reason, and every bias the method knows of
(sample rates, few samples) is a ``Caveat``: nothing the plan asks for is dropped silently.
"""

import datetime as dt
import importlib.metadata
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, TypeVar

import numpy as np

from credibility import indices, signals, spectral
from credibility.caveats import (
    FEW_SAMPLE_PARAMETERS,
    RATE_CONSEQUENCES,
    Caveat,
    Logged,
    epsilon_below_noise,
    few_samples,
    interpolated,
    rate_mismatch,
    require_epsilon,
)
from credibility.errors import CredibilityError, NotScorable, Reason
from credibility.logs import LogFile, SignalSpec, open_log
from credibility.plan import FrequencyTest, PerformanceTest, Plan, Test, TimeTest
from px4_logs import ARMING_STATE_ARMED

Outcome = Literal["pass", "fail", "could not be scored"]
Row = TypeVar("Row")

#: Bendat & Piersol (Random Data, table 9.6): the gain estimate |Ĥ| has a normalized random
#: error ε_r (the estimate's ``random_error``), 20/ln 10 · ε_r in dB, and the phase estimate
#: a standard deviation of ε_r radians.
_DB_PER_RELATIVE_ERROR = 20.0 / np.log(10.0)


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
    #: σ of the real curve's noise (``signals.noise_sigma``): the e_t of an exact model.
    noise_floor: float
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
    #: e_mag and e_pha an exact model would still have: the real response's random error.
    floor_mag_db: float
    floor_pha_deg: float
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


@dataclass(frozen=True)
class NotScored:
    """A test the logs could not score; ``reason`` is also among the report's caveats and
    ``detail`` is the bare message, for a caller that wants the error as before."""

    test: Test
    reason: Caveat
    detail: str


@dataclass(frozen=True, eq=False)
class Assessment:
    """The whole answer: per-test results, eq. (aveP) means, η_all, η_min and the verdicts.

    ``results`` holds the scored tests and ``not_scored`` the others (each in plan order);
    the indices are over the scored tests. ``eta_all`` and ``eta_min`` are None when the
    report could not be scored, and ``unscorable_reason`` says why.
    """

    plan: Plan
    logs: tuple[LogInfo, ...]
    results: tuple[Result, ...]
    not_scored: tuple[NotScored, ...]
    caveats: tuple[Caveat, ...]
    means: dict[str, float]
    eta_all: float | None
    eta_min: float | None
    unscorable_reason: str | None
    package_version: str
    created_utc: str
    #: The source tree's commit (" with uncommitted changes" when it differs), "" outside git.
    commit: str = ""

    @property
    def scorable(self) -> bool:
        """Enough tests were scored for a verdict (see ``unscorable_reason``)."""
        return self.unscorable_reason is None

    @property
    def meets_eps_min(self) -> bool:
        """η_min ≥ ε_min: the paper's condition for η_all to be meaningful (eq. (worse))."""
        return self.eta_min is not None and self.eta_min >= self.plan.eps_min

    @property
    def passes(self) -> bool:
        """η_all at or above the pass mark."""
        return self.eta_all is not None and self.eta_all >= self.plan.pass_mark

    @property
    def outcome(self) -> Outcome:
        """The verdict the exit code reports: η_min against ε_min over the scored tests."""
        if not self.scorable:
            return "could not be scored"
        return "pass" if self.meets_eps_min else "fail"

    def caveats_of(self, test: str) -> tuple[Caveat, ...]:
        """One test's warnings, for the marker on its section of the report."""
        return tuple(c for c in self.caveats if c.test == test)


def package_version() -> str:
    return importlib.metadata.version("hil-rig")


def source_commit() -> str:
    """The commit of the source tree this package runs from, so that a report says which
    code scored it; "" when it is not a git checkout (an installed wheel) or git is absent."""

    def git(*args: str) -> str:
        try:
            done = subprocess.run(["git", *args], cwd=Path(__file__).parent, capture_output=True,
                                  text=True, check=False, timeout=10)  # fmt: skip
        except (OSError, subprocess.TimeoutExpired):
            return ""
        return done.stdout.strip() if done.returncode == 0 else ""

    commit = git("rev-parse", "--short", "HEAD")
    if commit and git("status", "--porcelain", "--untracked-files=no"):
        commit += " with uncommitted changes"
    return commit


def steps(plan: Plan) -> int:
    """How many progress steps ``assess`` reports: one per distinct log, one per test."""
    return len(set(plan.logs.values())) + len(plan.tests)


def assess(
    plan: Plan, progress: Callable[[str], None] = lambda _: None, *, strict: bool = True
) -> Assessment:
    """Score every test of ``plan``; ``progress`` is called once per step with its label.

    A log that cannot be read is a ``CredibilityError``. A test the readable logs cannot
    score raises one too when ``strict`` (for a caller that needs every number); otherwise
    it is listed in ``not_scored`` and the indices are over the others, which is what the
    CLI does so the report can say what it could not compare.
    """
    opened: dict[Path, LogFile] = {}
    for path in dict.fromkeys(plan.logs.values()):
        progress(f"reading {path.name}")
        opened[path] = open_log(path)
    logs = {role: opened[path] for role, path in plan.logs.items()}
    caveats = [Caveat(None, "log_reader", w) for log in opened.values() for w in log.warnings]
    results: list[Result] = []
    not_scored: list[NotScored] = []
    for test in plan.tests:
        progress(f"{test.kind} test {test.name}")
        try:
            results.append(_run(test, logs, plan, caveats))
        except CredibilityError as exc:
            caveat = Caveat(test.name, _reason(exc), f"{exc}; not scored")
            not_scored.append(NotScored(test, caveat, str(exc)))
            caveats.append(caveat)
    if strict and not_scored:
        first = not_scored[0]
        more = f" (and {len(not_scored) - 1} more tests not scored)" if len(not_scored) > 1 else ""
        raise CredibilityError(f"test {first.test.name!r}: {first.detail}{more}")
    means = {
        kind: indices.rms_aggregate([r.eta for r in results if r.test.kind == kind])
        for kind in indices.KINDS
        if any(r.test.kind == kind for r in results)
    }
    reason = unscorable_reason(plan, results)
    return Assessment(
        plan=plan,
        logs=tuple(
            LogInfo(role, log.path, log.sha256, log.format, log.warnings)
            for role, log in logs.items()
        ),
        results=tuple(results),
        not_scored=tuple(not_scored),
        caveats=tuple(caveats),
        means=means,
        eta_all=None if reason else indices.overall_index(means, plan.weights),
        eta_min=None if reason else indices.minimum_index([r.eta for r in results]),
        unscorable_reason=reason,
        package_version=package_version(),
        created_utc=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        commit=source_commit(),
    )


def unscorable_reason(plan: Plan, results: list[Result]) -> str | None:
    """Why the scored tests cannot stand for the plan, or None when they can.

    Each kind of test the plan has must keep at least half of its tests: η̄ of a kind
    resting on a minority of the tests the plan chose for it no longer summarizes them,
    and a kind with none left leaves η_all undefined (its weight has nothing to weigh).
    """
    if not results:
        return f"none of the {len(plan.tests)} tests could be scored"
    for kind in indices.KINDS:
        total = sum(test.kind == kind for test in plan.tests)
        scored = sum(result.test.kind == kind for result in results)
        if scored == 0 and total:
            return f"no {kind} test (of {total}) could be scored: η̄_{kind[0]} is undefined"
        if 2 * scored < total:
            return (
                f"only {scored} of {total} {kind} tests could be scored: η̄_{kind[0]} would "
                "rest on fewer than half of them"
            )
    return None


def _reason(exc: CredibilityError) -> Reason:
    return exc.reason if isinstance(exc, NotScorable) else "unusable_signal"


def _run(test: Test, logs: dict[str, LogFile], plan: Plan, notes: list[Caveat]) -> Result:
    if isinstance(test, PerformanceTest):
        return _performance(test, logs, plan, notes)
    if isinstance(test, TimeTest):
        return _time(test, logs, plan, notes)
    return _frequency(test, logs, plan, notes)


def _rows(test: Test, row: Callable[[str], Row], notes: list[Caveat]) -> tuple[Row, ...]:
    """One row per sim, the assessed one first. A compared sim (outside the aggregates)
    that cannot be scored is left out with a caveat; the assessed one fails the test."""
    rows = []
    for role in test.roles.sims:
        try:
            rows.append(row(role))
        except CredibilityError as exc:
            if role == test.roles.sim:
                raise
            notes.append(Caveat(test.name, _reason(exc), f"{exc}; compared sim {role!r} left out"))
    return tuple(rows)


def _note(notes: list[Caveat], caveat: Caveat | None) -> None:
    if caveat is not None:
        notes.append(caveat)


def _windowed(
    log: LogFile, spec: SignalSpec, segment_s: tuple[float, float], plan: Plan
) -> signals.Signal:
    return signals.window(log.signal(spec), segment_s, plan.max_gap_s, spec.drop_nan)


#: ``vehicle_status.arming_state``, ARMING_STATE_ARMED when armed.
_ARMING_STATE = SignalSpec(path="vehicle_status.arming_state")


def _check_arming(log: LogFile, segment_s: tuple[float, float], armed: bool) -> None:
    """Raise ``state_mismatch`` unless ``log``'s vehicle is ``armed`` (or disarmed) over the
    whole of ``segment_s``: the state in force at its start and every change inside it."""
    status = log.signal(_ARMING_STATE)
    start_s, end_s = segment_s
    first = max(int(np.searchsorted(status.time_s, start_s, "right")) - 1, 0)
    last = int(np.searchsorted(status.time_s, end_s, "right"))
    held = (status.values[first:last] == ARMING_STATE_ARMED) == armed
    wanted = "armed" if armed else "disarmed"
    if status.time_s[0] > start_s:
        found = f"its arming state is not logged before {status.time_s[0]:g} s"
    elif not held.all():
        when = max(start_s, float(status.time_s[first + int(np.argmin(held))]))
        found = f"the vehicle is {'disarmed' if armed else 'armed'} at {when:g} s"
    else:
        return
    raise NotScorable(
        "state_mismatch",
        f"{log.path}: {found} (vehicle_status.arming_state), inside {start_s:g}-{end_s:g} s "
        f"where this test compares {'an' if armed else 'a'} {wanted} vehicle",
    )


def _performance_signal(
    test: PerformanceTest,
    log: LogFile,
    spec: SignalSpec,
    segment_s: tuple[float, float],
    plan: Plan,
) -> signals.Signal:
    """The test's window of one log, averaged to the test's ``average_hz`` when it has one
    (after the check that it holds the test's arming state, if the test names one)."""
    if test.armed is not None:
        _check_arming(log, segment_s, test.armed)
    sig = _windowed(log, spec, segment_s, plan)
    if test.average_hz is None:
        return sig
    return signals.interval_means(sig, 1.0 / test.average_hz)


# --- performance ---------------------------------------------------------------------------


def _statistic_values(test: PerformanceTest, sig: signals.Signal) -> np.ndarray:
    """The samples the parameter is computed from (high-passed when the test asks)."""
    if test.highpass_hz is None:
        return sig.values
    return signals.highpass(sig.values, sig.median_interval_s(), test.highpass_hz)


def _parameter(test: PerformanceTest, sig: signals.Signal, values: np.ndarray) -> float:
    if test.parameter == "mean":
        return float(values.mean())
    if test.parameter == "std":
        return float(values.std(ddof=1))
    assert test.steady_window_s is not None  # __post_init__ sets it with the segment
    metrics = signals.step_metrics(sig.time_s, values, test.settling_band, test.steady_window_s)
    return {
        "overshoot": metrics.overshoot_pct,
        "rise_time": metrics.rise_time_s,
        "settling_time": metrics.settling_time_s,
        "steady_state": metrics.steady_state,
    }[test.parameter]


def _performance_row(
    test: PerformanceTest, plan: Plan, role: str, p_e: float, p_s: float
) -> PerformanceRow:
    if test.threshold is not None:
        threshold, rule = test.threshold, "plan"
    elif p_e == 0.0 and p_s == 0.0:
        raise NotScorable(
            "unscorable_epsilon",
            f"p_e = p_s = 0 ({role!r}), so ε_p = K_p·|p_e| and its fallback K_p·|p_s| are 0 and "
            "η_p is undefined; give the test a 'threshold'",
        )
    else:
        assert test.k_p is not None  # load_plan gives every test the plan's k_p
        threshold = indices.performance_threshold(p_e, p_s, test.k_p)
        rule = "K_p·|p_e|" if p_e != 0.0 else "K_p·|p_s| (p_e = 0)"
    error = indices.performance_error(p_e, p_s)
    eta = indices.normalized_index(error, threshold, plan.pass_mark)
    return PerformanceRow(role, p_e, p_s, error, threshold, rule, eta)


def _performance(
    test: PerformanceTest, logs: dict[str, LogFile], plan: Plan, notes: list[Caveat]
) -> PerformanceResult:
    if test.parameter == "value":
        p_e = test.values[test.roles.real]
        rows = _rows(
            test, lambda role: _performance_row(test, plan, role, p_e, test.values[role]), notes
        )
        return PerformanceResult(test, rows)
    # __post_init__ requires the real signal and segment but for "value", and fills the sim's
    signal, segment_s = test.signal, test.segment_s
    signal_sim, segment_sim_s = test.signal_sim, test.segment_sim_s
    assert signal is not None
    assert segment_s is not None
    assert signal_sim is not None
    assert segment_sim_s is not None
    real_role = test.roles.real
    real = _performance_signal(test, logs[real_role], signal, segment_s, plan)
    real_values = _statistic_values(test, real)
    p_e = _parameter(test, real, real_values)
    consequence = RATE_CONSEQUENCES.get(test.parameter)
    sims: dict[str, signals.Signal] = {}

    def row(role: str) -> PerformanceRow:
        sim = sims[role] = _performance_signal(test, logs[role], signal_sim, segment_sim_s, plan)
        if consequence:
            real_logged, sim_logged = Logged.of(real_role, real), Logged.of(role, sim)
            _note(notes, rate_mismatch(test.name, real_logged, sim_logged, consequence))
        p_s = _parameter(test, sim, _statistic_values(test, sim))
        return _performance_row(test, plan, role, p_e, p_s)

    rows = _rows(test, row, notes)
    if test.parameter in FEW_SAMPLE_PARAMETERS:
        real_logged = Logged.of(real_role, real)
        assessed, eps = Logged.of(test.roles.sim, sims[test.roles.sim]), rows[0].threshold
        _note(
            notes, few_samples(test.name, test.parameter, real_logged, real_values, assessed, eps)
        )
    return PerformanceResult(test, rows)


# --- time ----------------------------------------------------------------------------------


def _alignment_shift(test: TimeTest, real_log: LogFile, sim_log: LogFile) -> float:
    """Seconds to add to the sim segment so its curve lines up with the real one."""
    align = test.align
    if align.method == "none":
        return 0.0
    # TimeTest.__post_init__ fills the alignment's signals and the sim segment
    assert align.signal is not None
    assert align.signal_sim is not None
    assert test.segment_sim_s is not None
    real = real_log.signal(align.signal)
    sim = sim_log.signal(align.signal_sim)
    (t_a, t_b), (s_a, s_b) = test.segment_s, test.segment_sim_s
    lag = align.max_lag_s
    if align.method == "event":
        level, direction = align.threshold, align.direction
        assert level is not None  # Alignment.__post_init__: an event needs its level
        t_real = signals.first_crossing(real, level, direction, (t_a - lag, t_b + lag))
        t_sim = signals.first_crossing(sim, level, direction, (s_a - lag, s_b + lag))
        return (t_sim - s_a) - (t_real - t_a)
    return signals.correlation_lag(real, sim, test.segment_s, s_a, lag, real.median_interval_s())


def _time(test: TimeTest, logs: dict[str, LogFile], plan: Plan, notes: list[Caveat]) -> TimeResult:
    real_role = test.roles.real
    real_log = logs[real_role]
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
        assert test.k_p is not None  # load_plan gives every test the plan's k_p
        threshold, rule = indices.range_threshold(y_e, test.k_p), "K_p·(max y_e − min y_e)"
    require_epsilon("ε_t", threshold, rule, test.unit)
    noise_floor = signals.noise_sigma(y_e)
    source = "σ of its noise from the curve's 4th differences"
    caveat = epsilon_below_noise(test.name, "ε_t", threshold, rule, noise_floor, source, test.unit)
    _note(notes, caveat)
    on_grid = Logged("the comparison grid t_1 … t_n", 1.0 / interval, n_t, duration)
    consequence = RATE_CONSEQUENCES["time"]
    _note(notes, interpolated(test.name, Logged.of(real_role, real), on_grid, consequence))

    # __post_init__ fills them from the real ones
    signal_sim, segment_sim_s = test.signal_sim, test.segment_sim_s
    assert signal_sim is not None
    assert segment_sim_s is not None

    def row(role: str) -> TimeRow:
        shift = _alignment_shift(test, real_log, logs[role])
        segment = (segment_sim_s[0] + shift, segment_sim_s[1] + shift)
        sim = _windowed(logs[role], signal_sim, segment, plan)
        _note(notes, interpolated(test.name, Logged.of(role, sim), on_grid, consequence))
        y_s = curve(sim, segment[0])
        error = indices.rms_error(y_e, y_s)
        return TimeRow(
            role=role,
            values=y_s,
            segment_s=segment,
            alignment_shift_s=shift,
            error=error,
            eta=indices.normalized_index(error, threshold, plan.pass_mark),
            theil_u=indices.theil_inequality(y_e, y_s),
        )

    zero_error = indices.rms_error(y_e, np.zeros_like(y_e))
    return TimeResult(
        test=test,
        grid_s=grid,
        real_values=y_e,
        threshold=threshold,
        threshold_rule=rule,
        noise_floor=noise_floor,
        rows=_rows(test, row, notes),
        zero_output_error=zero_error,
        zero_output_eta=indices.normalized_index(zero_error, threshold, plan.pass_mark),
    )


# --- frequency -----------------------------------------------------------------------------


def _frequency(
    test: FrequencyTest, logs: dict[str, LogFile], plan: Plan, notes: list[Caveat]
) -> FrequencyResult:
    real_role = test.roles.real
    rate_hz = (
        test.sample_rate_hz
        or _windowed(logs[real_role], test.output, test.segment_s, plan).rate_hz()
    )
    freqs = spectral.log_grid(test.band_hz, test.n_points)
    # __post_init__ fills them from the real ones
    input_sim, output_sim, segment_sim_s = test.input_sim, test.output_sim, test.segment_sim_s
    assert input_sim is not None
    assert output_sim is not None
    assert segment_sim_s is not None
    shortest_s = min(test.segment_s[1] - test.segment_s[0], segment_sim_s[1] - segment_sim_s[0])
    windows = test.windows_s or spectral.default_windows(shortest_s, test.band_hz)

    def estimate(
        role: str, input_spec: SignalSpec, output_spec: SignalSpec, segment_s: tuple[float, float]
    ) -> spectral.FrequencyResponseEstimate:
        """Input and output on one uniform grid (spectra need uniform samples)."""
        grid = np.arange(segment_s[0], segment_s[1], 1.0 / rate_hz)
        spectra = Logged("the spectra's uniform grid", rate_hz, grid.size, grid[-1] - grid[0])
        x, y = (_windowed(logs[role], spec, segment_s, plan) for spec in (input_spec, output_spec))
        consequence = RATE_CONSEQUENCES["frequency"]
        for sig in (x, y):
            _note(notes, interpolated(test.name, Logged.of(role, sig), spectra, consequence))
        return spectral.estimate_response(
            signals.resample(x, grid),
            signals.resample(y, grid),
            rate_hz,
            freqs,
            windows,
            test.overlap,
        )

    real = estimate(real_role, test.input, test.output, test.segment_s)

    def row(role: str) -> FrequencyRow:
        sim = estimate(role, input_sim, output_sim, segment_sim_s)
        return _compare_responses(test, real, sim, role, plan.pass_mark)

    rows = _rows(test, row, notes)
    assessed = rows[0]
    source = "W_γ-weighted random error of the real response"
    for symbol, eps, floor, given, unit in (
        ("ε_mag", assessed.eps_mag_db, assessed.floor_mag_db, test.threshold_mag_db, "dB"),
        ("ε_pha", assessed.eps_pha_deg, assessed.floor_pha_deg, test.threshold_phase_deg, "deg"),
    ):
        rule = _frequency_rule(given)
        _note(notes, epsilon_below_noise(test.name, symbol, eps, rule, floor, source, unit))
    return FrequencyResult(test, real, rate_hz, rows)


def _frequency_rule(given: float | None) -> str:
    """Where an ε of a frequency test came from."""
    return "plan" if given else "K_p·range of the real curve over the coherent grid"


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
    assert test.k_p is not None  # load_plan gives every test the plan's k_p
    eps_mag = test.threshold_mag_db or indices.range_threshold(m_e, test.k_p)
    eps_pha = test.threshold_phase_deg or indices.range_threshold(p_e, test.k_p)
    rules = {
        name: _frequency_rule(given)
        for name, given in (("ε_mag", test.threshold_mag_db), ("ε_pha", test.threshold_phase_deg))
    }
    require_epsilon("ε_mag", eps_mag, rules["ε_mag"], "dB")
    require_epsilon("ε_pha", eps_pha, rules["ε_pha"], "deg")
    # The error an exact model would still have: the real estimate's random error, weighted.
    random_error = real.random_error[included]
    rule = ", ".join(f"{name}: {how}" for name, how in rules.items())
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
        floor_mag_db=indices.weighted_rms_error(_DB_PER_RELATIVE_ERROR * random_error, 0.0, w),
        floor_pha_deg=indices.weighted_rms_error(np.degrees(random_error), 0.0, w),
        eta_mag=eta_mag,
        eta_pha=eta_pha,
        eta=indices.frequency_index(eta_mag, eta_pha),
        cifer_j=indices.cifer_cost(m_e, m_s, p_e, p_s, gamma2[included]),
    )
