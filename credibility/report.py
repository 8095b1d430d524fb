"""Rendering an ``Assessment``: a JSON summary for pipelines and one self-contained HTML file.

Plots are drawn with matplotlib's Agg canvas (no display, no pyplot state) and embedded as
base64 PNG, so the report opens offline and can be mailed as one file.
"""

import base64
import dataclasses
import enum
import hashlib
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jinja2
import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from credibility import indices, weakest
from credibility.assess import (
    Assessment,
    FrequencyResult,
    NotScored,
    PerformanceResult,
    Result,
    TimeResult,
)
from credibility.caveats import Caveat
from credibility.logs import SignalSpec
from credibility.plan import Test
from credibility.provenance import provenance_of

PAPER_W_GAMMA = "paper: W_γ = (1 − e^{−γ²}) / (1 − e^{−1}) on min(γ²_real, γ²_sim)"
CIFER_W_GAMMA = "Tischler & Remple: W_γ = [1.58 (1 − e^{−γ²})]², W_g = 1, W_p = 0.01745"


class ExitCode(enum.IntEnum):
    """What ``credibility report`` exits with, so a pipeline can tell the cases apart."""

    #: η_min ≥ ε_min over the scored tests.
    PASS = 0
    #: η_min < ε_min: a result, not an error.
    FAIL = 1
    #: The plan or a log cannot be read, or the command line is wrong; nothing is written.
    BAD_INPUT = 2
    #: Everything was read, but too few tests could be scored to give a verdict
    #: (``Assessment.unscorable_reason``); the report says which and why.
    NOT_SCORED = 3


def exit_code(assessment: Assessment) -> ExitCode:
    """The verdict as an exit code: pass, fail, or could not be scored."""
    return {
        "pass": ExitCode.PASS,
        "fail": ExitCode.FAIL,
        "could not be scored": ExitCode.NOT_SCORED,
    }[assessment.outcome]


def _caveat_dicts(caveats: tuple[Caveat, ...]) -> list[dict[str, Any]]:
    return [dataclasses.asdict(caveat) for caveat in caveats]


def _spec(spec: SignalSpec | None) -> dict[str, Any] | None:
    if spec is None:
        return None
    return {
        "path": spec.path,
        "scale": spec.scale,
        "convert": spec.convert,
        "drop_nan": spec.drop_nan,
    }


def _floats(values: np.ndarray) -> list[float]:
    return [float(v) for v in values]


def _identity(test: Test) -> dict[str, Any]:
    return {
        "name": test.name,
        "kind": test.kind,
        "real": test.roles.real,
        "sim": test.roles.sim,
        "compare": list(test.roles.compare),
        "k_p": test.k_p,
    }


def _not_scored_dict(item: NotScored) -> dict[str, Any]:
    return _identity(item.test) | {
        "scored": False,
        "eta": None,
        "passes_pass_mark": None,
        "not_scored": {"kind": item.reason.kind, "message": item.reason.message},
    }


def _test_dict(result: Result, pass_mark: float) -> dict[str, Any]:
    test: Test = result.test  # each branch below narrows it with the result
    common = _identity(test) | {
        "scored": True,
        "eta": result.eta,
        "passes_pass_mark": result.eta >= pass_mark,
    }
    if isinstance(result, PerformanceResult):
        test = result.test
        return common | {
            "parameter": test.parameter,
            "unit": test.unit,
            "signal": _spec(test.signal),
            "signal_sim": _spec(test.signal_sim),
            "segment_s": test.segment_s,
            "segment_sim_s": test.segment_sim_s,
            "highpass_hz": test.highpass_hz,
            "average_hz": test.average_hz,
            "settling_band": test.settling_band if test.parameter == "settling_time" else None,
            "steady_window_s": test.steady_window_s,
            "rows": [vars(row) for row in result.rows],
        }
    if isinstance(result, TimeResult):
        test = result.test
        align = test.align
        return common | {
            "unit": test.unit,
            "signal": _spec(test.signal),
            "signal_sim": _spec(test.signal_sim),
            "segment_s": test.segment_s,
            "n_t": result.n_t,
            "grid_interval_s": float(result.grid_s[1] - result.grid_s[0]),
            "smoothing": None
            if test.smoothing is None
            else {"method": "Savitzky–Golay", **vars(test.smoothing)},
            "alignment": {
                "method": align.method,
                "signal": _spec(align.signal),
                "signal_sim": _spec(align.signal_sim),
                "threshold": align.threshold if align.method == "event" else None,
                "direction": align.direction if align.method == "event" else None,
                "max_lag_s": align.max_lag_s,
            },
            "threshold": result.threshold,
            "threshold_rule": result.threshold_rule,
            "noise_floor": result.noise_floor,
            "zero_output": {"e_t": result.zero_output_error, "eta_t": result.zero_output_eta},
            "rows": [
                {
                    "role": row.role,
                    "segment_sim_s": row.segment_s,
                    "alignment_shift_s": row.alignment_shift_s,
                    "e_t": row.error,
                    "eta_t": row.eta,
                    "theil_u": row.theil_u,
                }
                for row in result.rows
            ],
        }
    test, real = result.test, result.real
    return common | {
        "input": _spec(test.input),
        "output": _spec(test.output),
        "input_sim": _spec(test.input_sim),
        "output_sim": _spec(test.output_sim),
        "segment_s": test.segment_s,
        "segment_sim_s": test.segment_sim_s,
        "sample_rate_hz": result.sample_rate_hz,
        "band_hz": test.band_hz,
        "freqs_hz": _floats(real.freqs_hz),
        "windows_s": list(real.windows_s),
        "averages_real": list(real.averages),
        "overlap": test.overlap,
        "combination": "inverse random-error variance, ε_r = sqrt(1−γ²)/(|γ| sqrt(2 n_d))",
        "coherence_min": test.coherence_min,
        "w_gamma": PAPER_W_GAMMA if test.coherence_weighting else "W_γ ≡ 1",
        "cifer_w_gamma": CIFER_W_GAMMA,
        "real_magnitude_db": _floats(real.magnitude_db),
        "real_coherence": _floats(real.coherence),
        "rows": [
            {
                "role": row.role,
                "excluded_hz": _floats(row.excluded_hz),
                "n_f": int(row.included.sum()),
                "e_mag_db": row.e_mag_db,
                "e_pha_deg": row.e_pha_deg,
                "eps_mag_db": row.eps_mag_db,
                "eps_pha_deg": row.eps_pha_deg,
                "threshold_rule": row.threshold_rule,
                "floor_mag_db": row.floor_mag_db,
                "floor_pha_deg": row.floor_pha_deg,
                "eta_mag": row.eta_mag,
                "eta_pha": row.eta_pha,
                "eta_f": row.eta,
                "cifer_j": row.cifer_j,
                "magnitude_db": _floats(row.estimate.magnitude_db),
                "phase_deg": _floats(row.phase_deg),
                "real_phase_deg": _floats(row.real_phase_deg),
                "coherence": _floats(row.estimate.coherence),
                "averages": list(row.estimate.averages),
            }
            for row in result.rows
        ],
    }


def _tests_in_plan_order(assessment: Assessment) -> list[tuple[Test, Result | NotScored]]:
    """Every test of the plan with its result or the reason it has none."""
    outcomes: dict[str, Result | NotScored] = {r.test.name: r for r in assessment.results}
    outcomes |= {item.test.name: item for item in assessment.not_scored}
    return [(test, outcomes[test.name]) for test in assessment.plan.tests]


def to_dict(assessment: Assessment) -> dict[str, Any]:
    """Everything the method used and found, as plain JSON types."""
    plan = assessment.plan
    tests = []
    for test, outcome in _tests_in_plan_order(assessment):
        entry = (
            _not_scored_dict(outcome)
            if isinstance(outcome, NotScored)
            else _test_dict(outcome, plan.pass_mark)
        )
        entry["warnings"] = _caveat_dicts(assessment.caveats_of(test.name))
        tests.append(entry)
    return {
        "package": "hil-rig credibility",
        "package_version": assessment.package_version,
        "created_utc": assessment.created_utc,
        "commit": assessment.commit,
        "plan": {
            "path": str(plan.path),
            "sha256": hashlib.sha256(plan.text.encode()).hexdigest(),
            "name": plan.name,
            "description": plan.description,
            "pass_mark": plan.pass_mark,
            "k_e": indices.pass_mark_gain(plan.pass_mark),
            "eps_min": plan.eps_min,
            "max_gap_s": plan.max_gap_s,
            "weights": dict(plan.weights),
            "weights_source": plan.weights_source,
            "text": plan.text,
        },
        "logs": [
            {
                "role": log.role,
                "path": str(log.path),
                "sha256": log.sha256,
                "format": log.format,
                "warnings": list(log.warnings),
                "provenance": provenance_of(log.path, log.format).to_dict(),
            }
            for log in assessment.logs
        ],
        "summary": {
            "outcome": assessment.outcome,
            "unscorable_reason": assessment.unscorable_reason,
            "tests": len(plan.tests),
            "scored": len(assessment.results),
            "not_scored": [item.test.name for item in assessment.not_scored],
            "not_scorable": [dataclasses.asdict(item) for item in plan.not_scorable],
            "warnings": len(assessment.caveats),
            "means": assessment.means,
            "eta_all": assessment.eta_all,
            "eta_min": assessment.eta_min,
            "eps_min": plan.eps_min,
            "meets_eps_min": assessment.meets_eps_min,
            "passes_pass_mark": assessment.passes,
            "exit_code": int(exit_code(assessment)),
        },
        "warnings": _caveat_dicts(assessment.caveats),
        "tests": tests,
        "weakest": [_weakness_dict(w) for w in weakest.rank(assessment)],
    }


def _weakness_dict(weakness: weakest.Weakness) -> dict[str, Any]:
    return {
        "test": weakness.test,
        "kind": weakness.kind,
        "eta": weakness.eta,
        "below_pass_mark": weakness.below_pass_mark,
        "findings": [
            {
                "role": finding.role,
                "eta": finding.eta,
                "why": finding.why,
                "diagnosis": dataclasses.asdict(finding.diagnosis) | _derived(finding.diagnosis),
            }
            for finding in weakness.findings
        ],
    }


def _derived(diagnosis: weakest.Diagnosis) -> dict[str, Any]:
    """The diagnosis's computed properties, so the JSON reader need not recompute them."""
    if isinstance(diagnosis, weakest.TimeDiagnosis):
        return {"dominant": diagnosis.dominant}
    if isinstance(diagnosis, weakest.PerformanceDiagnosis):
        return {
            "relative_error_pct": diagnosis.relative_error_pct,
            "threshold_pct": diagnosis.threshold_pct,
        }
    return {}


# --- plots ---------------------------------------------------------------------------------


def _png(figure: Figure) -> str:
    FigureCanvasAgg(figure)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=96, bbox_inches="tight")
    return base64.b64encode(buffer.getvalue()).decode("ascii")


#: Points per plotted curve: more than a PNG can show; long logs are decimated to this.
MAX_PLOT_POINTS = 4000


def _time_plot(result: TimeResult) -> str:
    figure = Figure(figsize=(8.0, 3.4))
    ax = figure.add_subplot()
    step = max(1, result.grid_s.size // MAX_PLOT_POINTS)
    t, y_e, eps = result.grid_s[::step], result.real_values[::step], result.threshold
    ax.fill_between(t, y_e - eps, y_e + eps, color="0.85", label=f"real ± ε_t ({eps:.3g})")
    ax.plot(t, y_e, color="k", lw=1.2, label=f"real ({result.test.roles.real})")
    for row in result.rows:
        ax.plot(t, row.values[::step], lw=1.0, label=f"{row.role} (η_t {row.eta:.1%})")
    ax.set_xlabel("time since t_a [s]" + (f" (every {step}th point shown)" if step > 1 else ""))
    ax.set_ylabel(f"{result.test.signal.path} [{result.test.unit}]")
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)
    return _png(figure)


def _shade_excluded(ax: Axes, freqs_hz: np.ndarray, included: np.ndarray) -> None:
    """Shade each excluded grid point out to the log-midpoints with its neighbours."""
    edges = np.sqrt(freqs_hz[:-1] * freqs_hz[1:])
    lower = np.concatenate(([freqs_hz[0]], edges))
    upper = np.concatenate((edges, [freqs_hz[-1]]))
    for lo, hi in zip(lower[~included], upper[~included], strict=True):
        ax.axvspan(lo, hi, color="tab:red", alpha=0.12, lw=0)


def _frequency_plot(result: FrequencyResult) -> str:
    figure = Figure(figsize=(8.0, 7.5))
    mag, pha, coh = figure.subplots(3, 1, sharex=True)
    f = result.real.freqs_hz
    first = result.rows[0]
    mag.semilogx(f, result.real.magnitude_db, "k", label=f"real ({result.test.roles.real})")
    pha.semilogx(f, first.real_phase_deg, "k")
    coh.semilogx(f, result.real.coherence, "k", label="real")
    for row in result.rows:
        mag.semilogx(f, row.estimate.magnitude_db, label=f"{row.role} (η_f {row.eta:.1%})")
        pha.semilogx(f, row.phase_deg)
        coh.semilogx(f, row.estimate.coherence, label=row.role)
        _shade_excluded(mag, f, row.included)
        _shade_excluded(pha, f, row.included)
        _shade_excluded(coh, f, row.included)
    coh.axhline(result.test.coherence_min, color="tab:red", ls="--", lw=1, label="ε_co")
    mag.set_ylabel("magnitude [dB]")
    pha.set_ylabel("phase [deg]")
    coh.set_ylabel("coherence γ²")
    coh.set_ylim(0.0, 1.02)
    coh.set_xlabel("frequency [Hz]  (shaded: excluded, γ² < ε_co)")
    mag.legend(fontsize=8)
    coh.legend(fontsize=8, loc="lower left")
    for ax in (mag, pha, coh):
        ax.grid(alpha=0.3, which="both")
    return _png(figure)


# --- HTML ----------------------------------------------------------------------------------

_CSS = """
body{font-family:system-ui,sans-serif;max-width:980px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.6em 0}
td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}
th{background:#eee} td:first-child,th:first-child{text-align:left}
.pass{color:#070;font-weight:bold} .fail{color:#b00;font-weight:bold}
pre{background:#f6f6f6;padding:0.6em;overflow-x:auto;font-size:0.85em}
.warn{color:#a60}
table.text td,table.text th{text-align:left}
ul.why{text-align:left;margin:0;padding-left:1.2em}
"""
#: The page template (``templates/report.html.j2``); every value is escaped there.
_TEMPLATES = jinja2.Environment(
    loader=jinja2.PackageLoader("credibility"), autoescape=True, undefined=jinja2.StrictUndefined,
    trim_blocks=True, lstrip_blocks=True,
)  # fmt: skip


@dataclass(frozen=True)
class Verdict:
    """A table cell that reads ``yes`` in green when ``ok``, else ``no`` in red."""

    ok: bool
    yes: str = "pass"
    no: str = "fail"
    kind: str = "verdict"


@dataclass(frozen=True)
class Code:
    """A table cell in monospace (a hash)."""

    text: str
    kind: str = "code"


@dataclass(frozen=True)
class Link:
    """A table cell linking to a test's section (``#test-<name>``)."""

    text: str
    target: str
    kind: str = "link"


@dataclass(frozen=True)
class Reasons:
    """A table cell listing ``(role, η, why)`` findings."""

    items: tuple[tuple[str, str, str], ...]
    kind: str = "reasons"


def _pct(value: float | None) -> str:
    return "—" if value is None else f"{100.0 * value:.2f} %"


def _performance_section(result: PerformanceResult, pass_mark: float) -> dict[str, Any]:
    test = result.test
    where = "values given in the plan"
    if test.signal:
        # required with a signal
        assert test.segment_s is not None
        assert test.segment_sim_s is not None
        where = (
            f"{test.signal.path}, segment {list(test.segment_s)} s "
            f"(sim {list(test.segment_sim_s)} s)"
        )
    hp = f", {test.highpass_hz:g} Hz high-pass" if test.highpass_hz else ""
    if test.average_hz:
        hp = f", averaged to {test.average_hz:g} Hz{hp}"
    rows = [
        [r.role, f"{r.p_e:.6g}", f"{r.p_s:.6g}", f"{r.error:.4g}",
         f"{r.threshold:.4g} ({r.threshold_rule})", _pct(r.eta), Verdict(r.eta >= pass_mark)]
        for r in result.rows
    ]  # fmt: skip
    return {"kind": "performance", "name": test.name, "parameter": test.parameter,
            "unit": test.unit, "where": where + hp, "k_p": f"{test.k_p:g}",
            "rows": rows}  # fmt: skip


def _time_section(result: TimeResult, pass_mark: float) -> dict[str, Any]:
    test = result.test
    smoothing = (
        f"Savitzky–Golay {test.smoothing.window_s:g} s, order {test.smoothing.polyorder}"
        if test.smoothing
        else "none"
    )
    align = test.align
    rows: list[list[Any]] = [[test.roles.real, "0", _pct(1.0), "0", "—", "—"]]
    rows += [
        [r.role, f"{r.error:.4g}", _pct(r.eta), f"{r.theil_u:.3f}",
         f"{r.alignment_shift_s:+.4f} s → [{r.segment_s[0]:.3f}, {r.segment_s[1]:.3f}]",
         Verdict(r.eta >= pass_mark)]
        for r in result.rows
    ]  # fmt: skip
    rows.append(["error bounds", f"{result.threshold:.4g}", _pct(pass_mark), "—", "—", "—"])
    rows.append(["zero output", f"{result.zero_output_error:.4g}",
                 _pct(result.zero_output_eta), "1.000", "—", "—"])  # fmt: skip
    max_lag = f" (max lag {align.max_lag_s:g} s)" if align.method != "none" else ""
    assert test.segment_sim_s is not None  # __post_init__ fills it
    text = (
        f"Segment {list(test.segment_s)} s (sim {list(test.segment_sim_s)} s before alignment); "
        f"n_t = {result.n_t}; ε_t = {result.threshold:.4g} ({result.threshold_rule}, "
        f"K_p = {test.k_p:g}); smoothing: {smoothing}; alignment: {align.method}{max_lag}."
    )
    return {"kind": "time", "name": test.name, "signal": test.signal.path, "unit": test.unit,
            "text": text, "rows": rows, "png": _time_plot(result)}  # fmt: skip


def _frequency_section(result: FrequencyResult, pass_mark: float) -> dict[str, Any]:
    test = result.test
    real = result.real
    rows = [
        [r.role, f"{int(r.included.sum())}/{r.included.size}",
         f"{r.e_mag_db:.4g} / {r.eps_mag_db:.4g}", _pct(r.eta_mag),
         f"{r.e_pha_deg:.4g} / {r.eps_pha_deg:.4g}", _pct(r.eta_pha), _pct(r.eta),
         f"{r.cifer_j:.2f}", Verdict(r.eta >= pass_mark)]
        for r in result.rows
    ]  # fmt: skip
    assert test.segment_sim_s is not None  # __post_init__ fills it
    text = (
        f"Segment {list(test.segment_s)} s (sim {list(test.segment_sim_s)} s), resampled at "
        f"{result.sample_rate_hz:g} Hz; {test.n_points} log-spaced points over "
        f"{list(test.band_hz)} Hz; windows {', '.join(f'{w:.3g}' for w in real.windows_s)} s "
        f"(real averages {list(real.averages)}, overlap {test.overlap:g}) combined by inverse "
        f"random-error variance; coherence gate ε_co = {test.coherence_min:g}; "
        f"η weighting {PAPER_W_GAMMA if test.coherence_weighting else 'W_γ ≡ 1'}; "
        f"CIFER J with {CIFER_W_GAMMA}; K_p = {test.k_p:g} ({result.rows[0].threshold_rule})."
    )
    excluded = [(r.role, ", ".join(f"{f:.3g}" for f in r.excluded_hz) or "none")
                for r in result.rows]  # fmt: skip
    return {"kind": "frequency", "name": test.name, "input": test.input.path,
            "output": test.output.path, "text": text, "rows": rows, "excluded": excluded,
            "png": _frequency_plot(result)}  # fmt: skip


def _weakest_rows(assessment: Assessment) -> list[list[Any]]:
    """Every test, lowest η first, with the reason its numbers give for each sim."""
    return [
        [str(rank), weakness.test, weakness.kind, _pct(weakness.eta),
         Verdict(not weakness.below_pass_mark, "pass", "below pass mark"),
         Reasons(tuple((f.role, _pct(f.eta), f.why) for f in weakness.findings))]
        for rank, weakness in enumerate(weakest.rank(assessment), start=1)
    ]  # fmt: skip


def _not_scored_section(item: NotScored) -> dict[str, Any]:
    return {"kind": "not_scored", "name": item.test.name, "test_kind": item.test.kind,
            "reason": item.reason.kind, "message": item.reason.message}  # fmt: skip


def _section(result: Result | NotScored, pass_mark: float) -> dict[str, Any]:
    if isinstance(result, NotScored):
        return _not_scored_section(result)
    if isinstance(result, PerformanceResult):
        return _performance_section(result, pass_mark)
    if isinstance(result, TimeResult):
        return _time_section(result, pass_mark)
    return _frequency_section(result, pass_mark)


def render_html(assessment: Assessment) -> str:
    """The whole report as one HTML string."""
    plan = assessment.plan
    summary_rows = [
        [f"η̄_{kind[0]} ({kind})", _pct(value), f"{plan.weights.get(kind, 0.0):g}"]
        for kind, value in assessment.means.items()
    ]
    summary_rows.append(["η_all (eq. (overall))", _pct(assessment.eta_all), "—"])
    summary_rows.append(["η_min (eq. (worse))", _pct(assessment.eta_min), "—"])
    sections = []
    for test, result in _tests_in_plan_order(assessment):
        section = _section(result, plan.pass_mark)
        section["caveats"] = [
            (caveat.kind, caveat.message)
            for caveat in assessment.caveats_of(test.name)
            if not isinstance(result, NotScored) or caveat != result.reason
        ]
        sections.append(section)
    return _TEMPLATES.get_template("report.html.j2").render(
        css=_CSS,
        plan=plan,
        outcome=assessment.outcome,
        unscorable_reason=assessment.unscorable_reason,
        scored=len(assessment.results),
        not_scored=len(assessment.not_scored),
        eta_all=_pct(assessment.eta_all),
        eta_min=_pct(assessment.eta_min),
        passes=Verdict(assessment.passes, "at or above", "below"),
        meets_eps_min=Verdict(assessment.meets_eps_min, "≥", "<"),
        pass_mark=_pct(plan.pass_mark),
        eps_min=_pct(plan.eps_min),
        k_e=f"{indices.pass_mark_gain(plan.pass_mark):.4g}",
        summary_rows=summary_rows,
        caveat_rows=[
            [Link(c.test, f"test-{c.test}") if c.test else "(report)", c.kind, c.message]
            for c in assessment.caveats
        ],
        weakest_rows=_weakest_rows(assessment),
        not_scorable_rows=[[item.name, item.kind, item.reason] for item in plan.not_scorable],
        sections=sections,
        package_version=assessment.package_version,
        created_utc=assessment.created_utc,
        commit=assessment.commit,
        plan_sha256=hashlib.sha256(plan.text.encode()).hexdigest(),
        log_rows=[
            [log.role, str(log.path), log.format, Code(log.sha256)] for log in assessment.logs
        ],
        origin_rows=[
            [log.role, *provenance_of(log.path, log.format).describe().values()]
            for log in assessment.logs
        ],
    )


def write_report(assessment: Assessment, out_dir: Path) -> tuple[Path, Path]:
    """Write ``<plan>.html`` and ``<plan>.json`` into ``out_dir``; return both paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    stem = assessment.plan.path.stem
    html_path, json_path = out_dir / f"{stem}.html", out_dir / f"{stem}.json"
    html_path.write_text(render_html(assessment), encoding="utf-8")
    json_path.write_text(
        json.dumps(to_dict(assessment), indent=2, ensure_ascii=False), encoding="utf-8"
    )
    return html_path, json_path
