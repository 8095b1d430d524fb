"""The campaign report: per-axis tables, the failure envelope, the slowest and failed cases.

Built from ``results.sqlite`` alone, so ``rig campaign report DIR`` regenerates it at any
time (also mid-campaign). Written as ``report.json`` (for scripts) and ``report.html``
(self-contained: the plot is an embedded PNG).
"""

from __future__ import annotations

import base64
import io
import json
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only, no display
import jinja2
import matplotlib.pyplot as plt
import numpy as np

from rig.campaign.results import CaseResult, read_provenance, read_results
from rig.campaign.schema import CREDIBILITY_METRICS, METRICS

#: How many of the slowest cases the report lists.
SLOWEST = 5
#: The report's page template (``templates/`` beside this module); HTML-escaped values.
_TEMPLATES = jinja2.Environment(
    loader=jinja2.PackageLoader("rig.campaign"), autoescape=True, undefined=jinja2.StrictUndefined,
    trim_blocks=True, lstrip_blocks=True,
)  # fmt: skip


def campaign_summary(
    results: list[CaseResult], provenance: Mapping[str, str] | None = None
) -> dict[str, Any]:
    """Everything the report shows, as plain data (this is ``report.json``); the η
    columns only where the campaign scored its cases with a credibility plan."""
    metrics = [
        m for m in METRICS if m not in CREDIBILITY_METRICS or any(m in r.metrics for r in results)
    ]
    axes: dict[str, dict[str, list[CaseResult]]] = defaultdict(lambda: defaultdict(list))
    for result in results:
        for axis, value in result.labels:
            axes[axis][value].append(result)
    statuses = {
        status: sum(r.status == status for r in results)
        for status in ("ok", "failed", "crashed", "hung")
    }
    return {
        "cases": len(results),
        "statuses": statuses,
        "provenance": dict(provenance or {}),
        "metrics": metrics,
        "axes": {
            axis: [_group_row(value, group, metrics) for value, group in values.items()]
            for axis, values in axes.items()
        },
        "envelope": failure_envelope(results),
        "slowest": [_case_row(r) for r in sorted(results, key=lambda r: -r.wall_s)[:SLOWEST]],
        "not_ok": [_case_row(r) for r in results if r.status != "ok"],
    }


def failure_envelope(results: list[CaseResult]) -> list[dict[str, Any]]:
    """Fault × onset → how many of its cases the vehicle survived (the run completed and
    the vehicle did not crash), over all the other axes."""
    cells: dict[tuple[str, str], list[bool]] = defaultdict(list)
    for result in results:
        labels = dict(result.labels)
        key = (labels.get("fault", "none"), labels.get("fault_onset_s", "-"))
        cells[key].append(survived(result))
    return [
        {"fault": fault, "onset_s": onset, "survived": sum(flags), "cases": len(flags)}
        for (fault, onset), flags in cells.items()
    ]


def survived(result: CaseResult) -> bool:
    return result.status in ("ok", "failed") and not result.metrics.get("crashed", True)


def _group_row(value: str, group: list[CaseResult], metrics: Sequence[str]) -> dict[str, Any]:
    row: dict[str, Any] = {
        "value": value,
        "cases": len(group),
        "pass_rate": sum(r.status == "ok" for r in group) / len(group),
    }
    for metric in metrics:
        numbers = [float(r.metrics[metric]) for r in group if r.metrics.get(metric) is not None]
        row[metric] = (
            {
                "mean": float(np.mean(numbers)),
                "min": float(np.min(numbers)),
                "max": float(np.max(numbers)),
                "n": len(numbers),
            }
            if numbers
            else None
        )
    return row


def _case_row(result: CaseResult) -> dict[str, Any]:
    return {
        "index": result.index,
        "case_id": result.case_id,
        "axes": dict(result.labels),
        "status": result.status,
        "reason": result.reason,
        "wall_s": result.wall_s,
        "run_dir": result.run_dir,
        "rig_log": result.rig_log,
        "autopilot_log": result.autopilot_log,
    }


def _worst(metric: str) -> str:
    """A credibility index is worst at its minimum, every other metric at its maximum."""
    return "min" if metric in CREDIBILITY_METRICS else "max"


def envelope_png(envelope: list[dict[str, Any]]) -> bytes:
    """Survival fraction per fault (rows) and onset (columns), as a PNG heat map."""
    faults = list(dict.fromkeys(cell["fault"] for cell in envelope))
    onsets = list(dict.fromkeys(cell["onset_s"] for cell in envelope))
    grid = np.full((len(faults), len(onsets)), np.nan)
    for cell in envelope:
        grid[faults.index(cell["fault"]), onsets.index(cell["onset_s"])] = (
            cell["survived"] / cell["cases"]
        )
    figure, ax = plt.subplots(figsize=(2 + 1.2 * len(onsets), 1 + 0.5 * len(faults)))
    image = ax.imshow(grid, cmap="RdYlGn", vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(onsets)), onsets)
    ax.set_yticks(range(len(faults)), faults)
    ax.set_xlabel("fault onset (s)")
    ax.set_title("failure envelope: fraction of cases survived")
    figure.colorbar(image, ax=ax)
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=90)
    plt.close(figure)
    return buffer.getvalue()


def write_report(out_dir: Path) -> Path:
    """Write ``report.json`` and ``report.html`` from the results; returns the HTML path."""
    summary = campaign_summary(read_results(out_dir), read_provenance(out_dir))
    (out_dir / "report.json").write_text(json.dumps(summary, indent=1))
    path = out_dir / "report.html"
    path.write_text(_html(summary, envelope_png(summary["envelope"]) if summary["cases"] else b""))
    return path


def _html(summary: dict[str, Any], png: bytes) -> str:
    """The page, from ``templates/campaign_report.html.j2`` (values formatted here)."""
    metrics, provenance = summary["metrics"], summary["provenance"]

    def stat(metric: str, cell: dict[str, float] | None) -> str:
        return "-" if cell is None else f"{cell['mean']:.3g} / {cell[_worst(metric)]:.3g}"

    def axis_row(r: dict[str, Any]) -> list[Any]:
        return [r["value"], r["cases"], f"{r['pass_rate']:.0%}", *(stat(m, r[m]) for m in metrics)]

    def case_row(r: dict[str, Any]) -> list[Any]:
        axes = ", ".join(f"{k}={v}" for k, v in r["axes"].items())
        return [r["index"], r["status"], r["reason"], f"{r['wall_s']:.1f}", axes,
                r["rig_log"] or r["run_dir"]]  # fmt: skip

    lists = (("Slowest cases", "slowest"), ("Cases not ok", "not_ok"))
    return _TEMPLATES.get_template("campaign_report.html.j2").render(
        cases=summary["cases"],
        statuses=summary["statuses"],
        credibility=provenance if "credibility_plan" in provenance else None,
        axis_header=["value", "cases", "pass rate", *(f"{m} mean / {_worst(m)}" for m in metrics)],
        axes={axis: [axis_row(r) for r in rows] for axis, rows in summary["axes"].items()},
        envelope=[
            [c["fault"], c["onset_s"], f"{c['survived']}/{c['cases']}"] for c in summary["envelope"]
        ],
        envelope_png=base64.b64encode(png).decode() if png else "",
        case_lists={title: [case_row(r) for r in summary[key]] for title, key in lists},
    )
