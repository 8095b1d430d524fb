"""Test plans (TOML): which logs, which signals and segments, and every setting of the method.

A plan names its logs by role (``real``, ``sim``, ``sim_low`` …) so the same plan scores a
rig run, a PX4 SITL run or a Gazebo run; ``credibility report PLAN --log sim=run.ulg``
replaces a role's path. Relative paths are relative to the plan file. The tables below are
the file's schema (:mod:`hil_config`): a misspelt key, a wrong type or a value out of range
is one line naming the file, the key and the value, never a silently ignored setting.
"""

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, Literal, get_args

from pydantic import AfterValidator, BeforeValidator, Field

from credibility import indices
from credibility.errors import CredibilityError
from credibility.logs import SignalSpec
from hil_config import (
    FieldError,
    NonNegative,
    Number,
    Positive,
    Text,
    parse,
    read_toml,
    table,
)

Parameter = Literal[
    "mean", "std", "overshoot", "rise_time", "settling_time", "steady_state", "value"
]
PARAMETERS: tuple[str, ...] = get_args(Parameter)
PARAMETER_UNITS = {"overshoot": "%", "rise_time": "s", "settling_time": "s"}


def _rising(pair: tuple[float, float]) -> tuple[float, float]:
    if not pair[0] < pair[1]:
        raise ValueError("must have start < end")
    return pair


#: ``[start, end]`` with start < end (seconds, or hertz for a band).
Span = Annotated[tuple[Number, Number], AfterValidator(_rising)]
#: A signal: ``"topic[.instance].field"``, or a table with its conversion.
Signal = Annotated[
    SignalSpec,
    BeforeValidator(lambda value: {"path": value} if isinstance(value, str) else value,
                    json_schema_input_type=str | SignalSpec),
]  # fmt: skip
Fraction = Annotated[Number, Field(ge=0, lt=1)]
Count = Annotated[int, Field(strict=True, ge=2)]


@dataclass(frozen=True)
class Comparison:
    """The logs a test compares: one real role, the assessed sim role, and extra sims
    (e.g. a low-precision model) shown beside it as in the paper's Table 2 but left out of
    the aggregates."""

    real: str = "real"
    sim: str = "sim"
    compare: tuple[str, ...] = ()

    @property
    def sims(self) -> tuple[str, ...]:
        return (self.sim, *self.compare)


@table
class Alignment:
    """How the sim segment is matched to the real one in time (the lag is reported).

    ``max_lag_s`` bounds the search; with ``method = "none"`` it bounds only the residual-lag
    search of the "where the model is weakest" page, which never moves the scored curve.
    The signals default to the test's; ``threshold`` is the level an ``event`` crosses.
    """

    method: Literal["none", "event", "xcorr"] = "none"
    signal: Signal | None = None
    signal_sim: Signal | None = None
    threshold: Number | None = None
    direction: Literal["rising", "falling"] = "rising"
    max_lag_s: Positive = 2.0

    def __post_init__(self) -> None:
        if self.method == "event" and self.threshold is None:
            raise FieldError("threshold", None, "method = 'event' needs the level it crosses")


@table
class Smoothing:
    """Savitzky–Golay smoothing of both curves before eq. (RQ)."""

    window_s: Positive
    polyorder: Annotated[int, Field(strict=True, ge=0)] = 3


@table(kw_only=True)
class _Test:
    """What every test has: its name, the log roles it compares, its k_p."""

    name: Text
    real: Text = "real"
    sim: Text = "sim"
    #: Extra sims shown beside the assessed one, outside the aggregates.
    compare: tuple[Text, ...] = ()
    #: None: the plan's ``k_p``.
    k_p: Positive | None = None

    @property
    def roles(self) -> Comparison:
        return Comparison(self.real, self.sim, self.compare)

    def _default(self, name: str, value: Any) -> None:
        """Fill a key the file left out with a value that depends on other keys."""
        if getattr(self, name) is None:
            object.__setattr__(self, name, value)


@table(kw_only=True)
class PerformanceTest(_Test):
    """η_p of eqs. (Ekey), (thres), (AAA) on one performance parameter; ``value`` takes
    the numbers from ``values`` (role → value) instead of a signal."""

    kind: Literal["performance"] = "performance"
    parameter: Parameter
    signal: Signal | None = None
    signal_sim: Signal | None = None
    segment_s: Span | None = None
    segment_sim_s: Span | None = None
    threshold: Positive | None = None
    highpass_hz: Positive | None = None
    #: Each log faster than this is averaged over 1/average_hz intervals before the statistic
    #: (:func:`credibility.signals.interval_means`): a SITL in lockstep logs sensor_combined
    #: per IMU sample (IMU_INTEG_RATE = its IMU rate) where the real vehicle logged PX4's
    #: means at IMU_INTEG_RATE, and a σ compares only at the same bandwidth.
    average_hz: Positive | None = None
    settling_band: Positive = 0.02
    #: None: a tenth of the segment.
    steady_window_s: Positive | None = None
    values: Mapping[str, Number] = field(default_factory=dict)
    unit: str | None = None
    #: The arming state the segment compares (True: armed, False: disarmed), checked in
    #: every log over its segment (``vehicle_status.arming_state``): a sim still flying when
    #: the real vehicle had disarmed is not compared (None: not checked).
    armed: bool | None = None

    def __post_init__(self) -> None:
        self._default("unit", PARAMETER_UNITS.get(self.parameter, ""))
        if self.parameter == "value":
            for role in (self.real, *self.roles.sims):
                if role not in self.values:
                    raise FieldError("values", dict(self.values), f"has no value for {role!r}")
            return
        for key in ("signal", "segment_s"):
            if getattr(self, key) is None:
                raise FieldError(key, None, f"is required by parameter = {self.parameter!r}")
        assert self.segment_s is not None  # checked just above
        self._default("signal_sim", self.signal)
        self._default("segment_sim_s", self.segment_s)
        self._default("steady_window_s", 0.1 * (self.segment_s[1] - self.segment_s[0]))


@table(kw_only=True)
class TimeTest(_Test):
    """η_t of eqs. (RQ), (EtThre), (CTime) on one curve over [t_a, t_b]."""

    kind: Literal["time"] = "time"
    signal: Signal
    signal_sim: Signal | None = None
    segment_s: Span
    segment_sim_s: Span | None = None
    threshold: Positive | None = None
    n_t: Count | None = None
    smoothing: Smoothing | None = None
    align: Alignment = Alignment()
    unit: str = ""

    def __post_init__(self) -> None:
        self._default("signal_sim", self.signal)
        self._default("segment_sim_s", self.segment_s)
        real, sim = self.segment_s, self.segment_sim_s
        assert sim is not None  # filled just above
        if abs((sim[1] - sim[0]) - (real[1] - real[0])) > 1e-9:
            raise FieldError("segment_sim_s", sim, f"must last as long as segment_s {list(real)}")
        if self.align.method != "none":
            align_signal = self.align.signal or self.signal
            object.__setattr__(self, "align", replace(
                self.align,
                signal=align_signal,
                signal_sim=self.align.signal_sim or self.align.signal or self.signal_sim,
                threshold=self.align.threshold or 0.0,
            ))  # fmt: skip


@table(kw_only=True)
class FrequencyTest(_Test):
    """η_f of eqs. (bbb) … (freqIndex) on one input→output response."""

    kind: Literal["frequency"] = "frequency"
    input: Signal
    output: Signal
    input_sim: Signal | None = None
    output_sim: Signal | None = None
    segment_s: Span
    segment_sim_s: Span | None = None
    band_hz: Span
    n_points: Count = 40
    windows_s: Annotated[tuple[Positive, ...], Field(min_length=1)] | None = None
    overlap: Fraction = 0.5
    sample_rate_hz: Positive | None = None
    #: None: the plan's ``coherence_min``.
    coherence_min: Fraction | None = None
    coherence_weighting: Annotated[bool, Field(strict=True)] = True
    threshold_mag_db: Positive | None = None
    threshold_phase_deg: Positive | None = None

    def __post_init__(self) -> None:
        self._default("input_sim", self.input)
        self._default("output_sim", self.output)
        self._default("segment_sim_s", self.segment_s)


Test = PerformanceTest | TimeTest | FrequencyTest


@table(kw_only=True)
class NotScorable:
    """A test this plan's logs cannot support, and why (``[[not_scorable]]``): the report
    lists it beside the scored ones, so a reader sees what the study left out on purpose
    (a log without GNSS has no position test) and not only what failed to score."""

    name: Text
    kind: indices.Kind
    reason: Text


@table
class PlanSettings:
    """``[plan]``: the name (default: the file's stem) and the method's settings."""

    name: Text | None = None
    description: str = ""
    #: The η at which a test passes (0.6 → K_e 0.75).
    pass_mark: Annotated[Number, Field(gt=0, lt=1)] = indices.DEFAULT_PASS_MARK
    eps_min: Annotated[Number, Field(gt=0, le=1)] = indices.DEFAULT_ETA_MIN
    #: Longer gaps in a logged signal inside a segment are an error.
    max_gap_s: Positive = 0.5
    k_p: Positive = indices.DEFAULT_K_P
    coherence_min: Fraction = indices.DEFAULT_COHERENCE_MIN


@table
class Weights:
    """α of eq. (overall): one per kind of test present, summing to 1."""

    performance: NonNegative = 0.0
    time: NonNegative = 0.0
    frequency: NonNegative = 0.0


@table
class PlanFile:
    """A plan file as written."""

    logs: Mapping[Text, Text]
    tests: Annotated[tuple[Annotated[Test, Field(discriminator="kind")], ...], Field(min_length=1)]
    plan: PlanSettings = PlanSettings()
    #: None: equal shares over the kinds in the plan.
    weights: Weights | None = None
    not_scorable: tuple[NotScorable, ...] = ()

    def __post_init__(self) -> None:
        names = [test.name for test in self.tests] + [item.name for item in self.not_scorable]
        duplicates = sorted({name for name in names if names.count(name) > 1})
        if duplicates:
            raise FieldError("tests", duplicates, "duplicate test names (tests, not_scorable)")
        for index, test in enumerate(self.tests):
            uses = [("real", test.real), ("sim", test.sim)]
            uses += [("compare", role) for role in test.compare]
            for key, role in uses:
                if role not in self.logs:
                    known = sorted(self.logs)
                    raise FieldError(f"tests[{index}].{key}", role, f"not in [logs] {known}")


@dataclass(frozen=True)
class Plan:
    """A parsed, checked plan. ``text`` is kept verbatim for the report's provenance."""

    path: Path
    text: str
    name: str
    description: str
    pass_mark: float
    eps_min: float
    max_gap_s: float
    weights: Mapping[str, float]
    weights_source: str
    logs: Mapping[str, Path]
    tests: tuple[Test, ...]
    not_scorable: tuple[NotScorable, ...] = ()


def load_plan(path: Path, log_overrides: Mapping[str, Path] | None = None) -> Plan:
    """Read and check a plan; ``log_overrides`` (role → path) replace the plan's log paths."""
    path = Path(path)
    document, _ = read_toml(path, path.parent, kind="plan", error=CredibilityError)
    file = parse(PlanFile, document, str(path), CredibilityError)
    settings = file.plan
    logs = {role: (path.parent / log).resolve() for role, log in file.logs.items()}
    for role, override in (log_overrides or {}).items():
        if role not in logs:
            raise CredibilityError(
                f"--log {role}=…: the plan has no log role {role!r}; roles: {sorted(logs)}"
            )
        logs[role] = Path(override).resolve()
    tests = tuple(_with_plan_defaults(test, settings) for test in file.tests)
    weights, weights_source = _weights(file.weights, path, {t.kind for t in tests})
    return Plan(
        path=path,
        text=path.read_text(encoding="utf-8"),
        name=settings.name or path.stem,
        description=settings.description,
        pass_mark=settings.pass_mark,
        eps_min=settings.eps_min,
        max_gap_s=settings.max_gap_s,
        weights=weights,
        weights_source=weights_source,
        logs=logs,
        tests=tests,
        not_scorable=file.not_scorable,
    )


def _with_plan_defaults(test: Test, settings: PlanSettings) -> Test:
    """The test with the plan-wide k_p and coherence_min where it sets none."""
    test = replace(test, k_p=test.k_p or settings.k_p)
    if isinstance(test, FrequencyTest) and test.coherence_min is None:
        test = replace(test, coherence_min=settings.coherence_min)
    return test


def with_weights(plan: Plan, weights: Mapping[str, float], source: str) -> Plan:
    """``plan`` with the α of eq. (overall) replaced, e.g. from the command line.

    Unlike the plan file, which must sum to 1, these are relative: each ≥ 0, their sum > 0,
    normalized to 1 (the report's note says so). A kind with tests may get 0, which leaves
    it out of η_all on purpose; it still counts in η_min. ``source`` names the origin in
    errors and in the report (``--weights 0.3,0.3,0.4``).
    """
    for kind, alpha in weights.items():
        if kind not in indices.KINDS:
            raise CredibilityError(
                f"{source}: unknown kind {kind!r}; expected one of {indices.KINDS}"
            )
        if not math.isfinite(alpha) or alpha < 0.0:
            raise CredibilityError(f"{source}: {kind} = {alpha!r} must be a finite number ≥ 0")
    kinds = {test.kind for test in plan.tests}
    merged = {kind: weights.get(kind, plan.weights.get(kind, 0.0)) for kind in indices.KINDS}
    for kind, alpha in merged.items():
        if alpha > 0.0 and kind not in kinds:
            raise CredibilityError(f"{source}: {kind} = {alpha:g} but the plan has no {kind} tests")
    total = sum(merged.values())
    if total <= 0.0:
        raise CredibilityError(f"{source}: the weights sum to 0; at least one must be > 0")
    notes = [source]
    if abs(total - 1.0) > 1e-9:
        notes.append(f"normalized from sum {total:g}")
    notes += [
        f"{kind} tests weighted 0, left out of η_all (still in η_min)"
        for kind in indices.KINDS
        if kind in kinds and merged[kind] == 0.0
    ]
    normalized: dict[str, float] = {
        kind: alpha / total for kind, alpha in merged.items() if kind in kinds
    }
    return replace(plan, weights=normalized, weights_source="; ".join(notes))


def _weights(table: Weights | None, path: Path, kinds: set[str]) -> tuple[dict[str, float], str]:
    """α of eq. (overall); without a [weights] table, equal shares over the kinds present."""
    if table is None:
        present = [k for k in indices.KINDS if k in kinds]
        return {k: 1.0 / len(present) for k in present}, "equal over the kinds in the plan"
    weights = {kind: getattr(table, kind) for kind in indices.KINDS}
    indices.check_weights(weights, f"{path} [weights]")
    for kind in indices.KINDS:
        if weights[kind] > 0.0 and kind not in kinds:
            raise CredibilityError(
                f"{path} [weights]: {kind} = {weights[kind]:g} but the plan has no {kind} tests"
            )
        if weights[kind] == 0.0 and kind in kinds:
            raise CredibilityError(
                f"{path} [weights]: the plan has {kind} tests but no weight for them"
            )
    return weights, "plan"
