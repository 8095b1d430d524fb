"""The campaign report: per-axis tables, the failure envelope, the slowest and failed cases.

Built from ``results.sqlite`` alone, so ``rig campaign report DIR`` regenerates it at any
time (also mid-campaign). Written as ``report.json`` (for scripts) and ``report.html``
(self-contained: the plot is an embedded PNG).
"""

from __future__ import annotations

import base64
import html
import io
import json
from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt
import numpy as np

from rig.apps.campaign import (
    CREDIBILITY_METRICS,
    METRICS,
    CaseResult,
    read_provenance,
    read_results,
)

#: How many of the slowest cases the report lists.
SLOWEST = 5


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


def _group_row(value: str, group: list[CaseResult], metrics: list[str]) -> dict[str, Any]:
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
    def table(header: list[str], rows: list[list[Any]]) -> str:
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = "".join(
            "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>"
            for row in rows
        )
        return f"<table><tr>{head}</tr>{body}</table>"

    def stat(metric: str, cell: dict[str, float] | None) -> str:
        if cell is None:
            return "-"
        return f"{cell['mean']:.3g} / {cell[_worst(metric)]:.3g}"

    metrics = summary["metrics"]

    parts = [
        f"<h1>Campaign report</h1><p>{summary['cases']} cases: "
        + ", ".join(f"{n} {s}" for s, n in summary["statuses"].items())
        + "</p>"
    ]
    if "credibility_plan" in summary["provenance"]:
        provenance = summary["provenance"]
        parts.append(
            f"<p>Credibility: plan {html.escape(provenance['credibility_plan'])} "
            f"(sha256 {provenance['credibility_plan_sha256']}), the case's "
            f"{html.escape(provenance['credibility_log'])}.ulg as role "
            f"{html.escape(provenance['credibility_role'])!r}</p>"
        )
    for axis, rows in summary["axes"].items():
        parts.append(f"<h2>Axis {html.escape(axis)}</h2>")
        parts.append(
            table(
                ["value", "cases", "pass rate", *(f"{m} mean / {_worst(m)}" for m in metrics)],
                [
                    [
                        r["value"],
                        r["cases"],
                        f"{r['pass_rate']:.0%}",
                        *(stat(m, r[m]) for m in metrics),
                    ]
                    for r in rows
                ],
            )
        )
    parts.append("<h2>Failure envelope</h2>")
    parts.append(
        table(
            ["fault", "onset (s)", "survived"],
            [
                [c["fault"], c["onset_s"], f"{c['survived']}/{c['cases']}"]
                for c in summary["envelope"]
            ],
        )
    )
    if png:
        parts.append(
            f'<img alt="failure envelope" src="data:image/png;base64,'
            f'{base64.b64encode(png).decode()}">'
        )
    for title, key in (("Slowest cases", "slowest"), ("Cases not ok", "not_ok")):
        parts.append(f"<h2>{title}</h2>")
        parts.append(
            table(
                ["case", "status", "reason", "wall (s)", "axes", "logs"],
                [
                    [
                        r["index"],
                        r["status"],
                        r["reason"],
                        f"{r['wall_s']:.1f}",
                        ", ".join(f"{k}={v}" for k, v in r["axes"].items()),
                        r["rig_log"] or r["run_dir"],
                    ]
                    for r in summary[key]
                ],
            )
        )
    style = "table{border-collapse:collapse}td,th{border:1px solid #999;padding:2px 6px}"
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>Campaign report</title>"
        f"<style>{style}</style></head><body>{''.join(parts)}</body></html>"
    )
