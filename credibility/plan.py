"""Test plans (TOML): which logs, which signals and segments, and every setting of the method.

A plan names its logs by role (``real``, ``sim``, ``sim_low`` …) so the same plan scores a
rig run, a PX4 SITL run or a Gazebo run; ``credibility report PLAN --log sim=run.ulg``
replaces a role's path. Relative paths are relative to the plan file. Every key is checked:
a misspelt key is an error, not a silently ignored setting.
"""

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from credibility import indices
from credibility.errors import CredibilityError
from credibility.logs import CONVERSIONS, SignalSpec

PARAMETERS = ("mean", "std", "overshoot", "rise_time", "settling_time", "steady_state", "value")
PARAMETER_UNITS = {"overshoot": "%", "rise_time": "s", "settling_time": "s"}
ALIGN_METHODS = ("none", "event", "xcorr")


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


@dataclass(frozen=True)
class Alignment:
    """How the sim segment is matched to the real one in time (the lag is reported).

    ``max_lag_s`` bounds the search; with ``method = "none"`` it bounds only the residual-lag
    search of the "where the model is weakest" page, which never moves the scored curve.
    """

    method: str = "none"
    signal: SignalSpec | None = None
    signal_sim: SignalSpec | None = None
    threshold: float = 0.0
    direction: str = "rising"
    max_lag_s: float = 2.0


@dataclass(frozen=True)
class Smoothing:
    """Savitzky–Golay smoothing of both curves before eq. (RQ)."""

    window_s: float
    polyorder: int = 3


@dataclass(frozen=True)
class PerformanceTest:
    """η_p of eqs. (Ekey), (thres), (AAA) on one performance parameter."""

    name: str
    roles: Comparison
    parameter: str
    signal: SignalSpec | None = None
    signal_sim: SignalSpec | None = None
    segment_s: tuple[float, float] | None = None
    segment_sim_s: tuple[float, float] | None = None
    k_p: float = indices.DEFAULT_K_P
    threshold: float | None = None
    highpass_hz: float | None = None
    settling_band: float = 0.02
    steady_window_s: float | None = None
    values: Mapping[str, float] = field(default_factory=dict)
    unit: str = ""
    kind: str = "performance"


@dataclass(frozen=True)
class TimeTest:
    """η_t of eqs. (RQ), (EtThre), (CTime) on one curve over [t_a, t_b]."""

    name: str
    roles: Comparison
    signal: SignalSpec
    signal_sim: SignalSpec
    segment_s: tuple[float, float]
    segment_sim_s: tuple[float, float]
    k_p: float = indices.DEFAULT_K_P
    threshold: float | None = None
    n_t: int | None = None
    smoothing: Smoothing | None = None
    alignment: Alignment = Alignment()
    unit: str = ""
    kind: str = "time"


@dataclass(frozen=True)
class FrequencyTest:
    """η_f of eqs. (bbb) … (freqIndex) on one input→output response."""

    name: str
    roles: Comparison
    input: SignalSpec
    output: SignalSpec
    input_sim: SignalSpec
    output_sim: SignalSpec
    segment_s: tuple[float, float]
    segment_sim_s: tuple[float, float]
    band_hz: tuple[float, float]
    n_points: int = 40
    windows_s: tuple[float, ...] | None = None
    overlap: float = 0.5
    sample_rate_hz: float | None = None
    coherence_min: float = indices.DEFAULT_COHERENCE_MIN
    coherence_weighting: bool = True
    k_p: float = indices.DEFAULT_K_P
    threshold_mag_db: float | None = None
    threshold_phase_deg: float | None = None
    kind: str = "frequency"


Test = PerformanceTest | TimeTest | FrequencyTest


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


class _Table:
    """A TOML table being read: typed getters whose errors name the file and the key."""

    def __init__(self, data: Mapping[str, Any], where: str) -> None:
        self.data = dict(data)
        self.where = where
        self.used: set[str] = set()

    def get(self, key: str, kind: type | tuple[type, ...], default: Any = None) -> Any:
        self.used.add(key)
        if key not in self.data:
            return default
        value = self.data[key]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
            raise CredibilityError(f"{self.where}: {key} = {value!r} has the wrong type")
        return value

    def require(self, key: str, kind: type | tuple[type, ...]) -> Any:
        if key not in self.data:
            raise CredibilityError(f"{self.where}: missing required key {key!r}")
        return self.get(key, kind)

    def number(self, key: str, default: float | None = None, positive: bool = True) -> Any:
        value = self.get(key, float, default)
        if value is not None and positive and not value > 0.0:
            raise CredibilityError(f"{self.where}: {key} = {value!r} must be > 0")
        return value

    def pair(self, key: str, required: bool = True) -> tuple[float, float] | None:
        value = self.require(key, list) if required else self.get(key, list)
        if value is None:
            return None
        if len(value) != 2 or not all(isinstance(v, int | float) for v in value):
            raise CredibilityError(f"{self.where}: {key} = {value!r} must be [start, end]")
        start, end = float(value[0]), float(value[1])
        if not start < end:
            raise CredibilityError(f"{self.where}: {key} = {value!r} must have start < end")
        return start, end

    def signal(self, key: str, required: bool = True) -> SignalSpec | None:
        value = self.require(key, (str, dict)) if required else self.get(key, (str, dict))
        if value is None:
            return None
        if isinstance(value, str):
            spec = SignalSpec(value)
        else:
            sub = _Table(value, f"{self.where}: {key}")
            convert = sub.get("convert", str)
            if convert is not None and convert not in CONVERSIONS:
                raise CredibilityError(
                    f"{sub.where}: convert = {convert!r} is unknown; known: {sorted(CONVERSIONS)}"
                )
            spec = SignalSpec(
                sub.require("path", str),
                scale=sub.get("scale", float, 1.0),
                convert=convert,
                drop_nan=sub.get("drop_nan", bool, False),
            )
            sub.finish()
        spec.parts()  # the path syntax is checked now, not when the log is read
        return spec

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise CredibilityError(f"{self.where}: unknown key(s) {', '.join(unknown)}")


def load_plan(path: Path, log_overrides: Mapping[str, Path] | None = None) -> Plan:
    """Read and check a plan; ``log_overrides`` (role → path) replace the plan's log paths."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise CredibilityError(f"{path}: cannot read plan ({exc.strerror})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CredibilityError(f"{path}: invalid TOML ({exc})") from None
    root = _Table(data, str(path))
    head = _Table(root.get("plan", dict, {}), f"{path} [plan]")
    name = head.get("name", str, path.stem)
    description = head.get("description", str, "")
    pass_mark = head.get("pass_mark", float, indices.DEFAULT_PASS_MARK)
    indices.pass_mark_gain(pass_mark)  # checks 0 < pass_mark < 1
    eps_min = head.get("eps_min", float, indices.DEFAULT_ETA_MIN)
    if not 0.0 < eps_min <= 1.0:
        raise CredibilityError(f"{head.where}: eps_min = {eps_min!r} must lie in (0, 1]")
    max_gap_s = head.number("max_gap_s", 0.5)
    defaults = {
        "k_p": head.number("k_p", indices.DEFAULT_K_P),
        "coherence_min": head.get("coherence_min", float, indices.DEFAULT_COHERENCE_MIN),
    }
    head.finish()

    logs_table = _Table(root.require("logs", dict), f"{path} [logs]")
    logs = {
        role: (path.parent / logs_table.require(role, str)).resolve()
        for role in list(logs_table.data)
    }
    logs_table.finish()
    for role, override in (log_overrides or {}).items():
        if role not in logs:
            raise CredibilityError(
                f"--log {role}=…: the plan has no log role {role!r}; roles: {sorted(logs)}"
            )
        logs[role] = Path(override).resolve()

    raw_tests = root.require("tests", list)
    if not raw_tests:
        raise CredibilityError(f"{path}: the plan has no [[tests]]")
    tests = tuple(
        _parse_test(raw, f"{path} tests[{i}]", defaults) for i, raw in enumerate(raw_tests)
    )
    names = [t.name for t in tests]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise CredibilityError(f"{path}: duplicate test names {duplicates}")
    for test in tests:
        for role in (test.roles.real, *test.roles.sims):
            if role not in logs:
                raise CredibilityError(
                    f"{path}: test {test.name!r} uses log role {role!r}, "
                    f"not in [logs] {sorted(logs)}"
                )

    kinds = {t.kind for t in tests}
    weights, weights_source = _weights(root, path, kinds)
    root.finish()
    return Plan(
        path=path,
        text=text,
        name=name,
        description=description,
        pass_mark=pass_mark,
        eps_min=eps_min,
        max_gap_s=max_gap_s,
        weights=weights,
        weights_source=weights_source,
        logs=logs,
        tests=tests,
    )


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
    normalized = {kind: alpha / total for kind, alpha in merged.items() if kind in kinds}
    return replace(plan, weights=normalized, weights_source="; ".join(notes))


def _weights(root: _Table, path: Path, kinds: set[str]) -> tuple[dict[str, float], str]:
    """α of eq. (overall); without a [weights] table, equal shares over the kinds present."""
    raw = root.get("weights", dict)
    if raw is None:
        present = [k for k in indices.KINDS if k in kinds]
        return {k: 1.0 / len(present) for k in present}, "equal over the kinds in the plan"
    table = _Table(raw, f"{path} [weights]")
    weights = {kind: table.get(kind, float, 0.0) for kind in indices.KINDS}
    table.finish()
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


def _parse_test(raw: Any, where: str, defaults: Mapping[str, float]) -> Test:
    if not isinstance(raw, dict):
        raise CredibilityError(f"{where}: each [[tests]] entry must be a table")
    table = _Table(raw, where)
    name = table.require("name", str)
    table.where = f"{where} ({name})"
    kind = table.require("kind", str)
    compare = table.get("compare", list, [])
    if not all(isinstance(c, str) for c in compare):
        raise CredibilityError(f"{table.where}: compare = {compare!r} must list log roles")
    roles = Comparison(table.get("real", str, "real"), table.get("sim", str, "sim"), tuple(compare))
    k_p = table.number("k_p", defaults["k_p"])
    if kind == "performance":
        test = _performance(table, name, roles, k_p)
    elif kind == "time":
        test = _time(table, name, roles, k_p)
    elif kind == "frequency":
        test = _frequency(table, name, roles, k_p, defaults["coherence_min"])
    else:
        raise CredibilityError(f"{table.where}: kind = {kind!r}; expected one of {indices.KINDS}")
    table.finish()
    return test


def _performance(table: _Table, name: str, roles: Comparison, k_p: float) -> PerformanceTest:
    parameter = table.require("parameter", str)
    if parameter not in PARAMETERS:
        raise CredibilityError(
            f"{table.where}: parameter = {parameter!r}; expected one of {PARAMETERS}"
        )
    unit = table.get("unit", str, PARAMETER_UNITS.get(parameter, ""))
    threshold = table.number("threshold")
    if parameter == "value":
        values = {role: table.require(f"{role}_value", float) for role in (roles.real, *roles.sims)}
        return PerformanceTest(
            name, roles, parameter, k_p=k_p, threshold=threshold, values=values, unit=unit
        )
    signal = table.signal("signal")
    segment = table.pair("segment_s")
    steady_window_s = table.number("steady_window_s")
    return PerformanceTest(
        name,
        roles,
        parameter,
        signal=signal,
        signal_sim=table.signal("signal_sim", required=False) or signal,
        segment_s=segment,
        segment_sim_s=table.pair("segment_sim_s", required=False) or segment,
        k_p=k_p,
        threshold=threshold,
        highpass_hz=table.number("highpass_hz"),
        settling_band=table.number("settling_band", 0.02),
        steady_window_s=steady_window_s or 0.1 * (segment[1] - segment[0]),
        unit=unit,
    )


def _time(table: _Table, name: str, roles: Comparison, k_p: float) -> TimeTest:
    signal = table.signal("signal")
    signal_sim = table.signal("signal_sim", required=False) or signal
    segment = table.pair("segment_s")
    segment_sim = table.pair("segment_sim_s", required=False) or segment
    if abs((segment_sim[1] - segment_sim[0]) - (segment[1] - segment[0])) > 1e-9:
        raise CredibilityError(
            f"{table.where}: segment_sim_s {list(segment_sim)} and segment_s {list(segment)} "
            "must have the same duration"
        )
    n_t = table.get("n_t", int)
    if n_t is not None and n_t < 2:
        raise CredibilityError(f"{table.where}: n_t = {n_t} must be ≥ 2")
    smoothing = None
    raw = table.get("smoothing", dict)
    if raw is not None:
        sub = _Table(raw, f"{table.where}: smoothing")
        smoothing = Smoothing(sub.number("window_s", None) or 0.0, sub.get("polyorder", int, 3))
        if smoothing.window_s <= 0.0:
            raise CredibilityError(f"{sub.where}: missing window_s > 0")
        sub.finish()
    alignment = Alignment()
    raw = table.get("align", dict)
    if raw is not None:
        sub = _Table(raw, f"{table.where}: align")
        method = sub.require("method", str)
        if method not in ALIGN_METHODS:
            raise CredibilityError(f"{sub.where}: method = {method!r}; expected {ALIGN_METHODS}")
        direction = sub.get("direction", str, "rising")
        if direction not in ("rising", "falling"):
            raise CredibilityError(f"{sub.where}: direction = {direction!r}; rising or falling")
        align_signal = sub.signal("signal", required=False)
        alignment = Alignment(
            method=method,
            signal=align_signal or signal,
            signal_sim=sub.signal("signal_sim", required=False) or align_signal or signal_sim,
            threshold=sub.require("threshold", float) if method == "event" else 0.0,
            direction=direction,
            max_lag_s=sub.number("max_lag_s", 2.0),
        )
        sub.finish()
    return TimeTest(
        name,
        roles,
        signal=signal,
        signal_sim=signal_sim,
        segment_s=segment,
        segment_sim_s=segment_sim,
        k_p=k_p,
        threshold=table.number("threshold"),
        n_t=n_t,
        smoothing=smoothing,
        alignment=alignment,
        unit=table.get("unit", str, ""),
    )


def _frequency(
    table: _Table, name: str, roles: Comparison, k_p: float, coherence_min: float
) -> FrequencyTest:
    input_spec = table.signal("input")
    output_spec = table.signal("output")
    segment = table.pair("segment_s")
    windows = table.get("windows_s", list)
    if windows is not None and (
        not windows or not all(isinstance(w, int | float) and w > 0 for w in windows)
    ):
        raise CredibilityError(f"{table.where}: windows_s = {windows!r} must list positive seconds")
    coherence_min = table.get("coherence_min", float, coherence_min)
    if not 0.0 <= coherence_min < 1.0:
        raise CredibilityError(
            f"{table.where}: coherence_min = {coherence_min!r} must be in [0, 1)"
        )
    n_points = table.get("n_points", int, 40)
    if n_points < 2:
        raise CredibilityError(f"{table.where}: n_points = {n_points} must be ≥ 2")
    return FrequencyTest(
        name,
        roles,
        input=input_spec,
        output=output_spec,
        input_sim=table.signal("input_sim", required=False) or input_spec,
        output_sim=table.signal("output_sim", required=False) or output_spec,
        segment_s=segment,
        segment_sim_s=table.pair("segment_sim_s", required=False) or segment,
        band_hz=table.pair("band_hz"),
        n_points=n_points,
        windows_s=tuple(float(w) for w in windows) if windows else None,
        overlap=table.get("overlap", float, 0.5),
        sample_rate_hz=table.number("sample_rate_hz"),
        coherence_min=coherence_min,
        coherence_weighting=table.get("coherence_weighting", bool, True),
        k_p=k_p,
        threshold_mag_db=table.number("threshold_mag_db"),
        threshold_phase_deg=table.number("threshold_phase_deg"),
    )
