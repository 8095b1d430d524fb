"""The results pages, rendered from the JSON the measuring commands write, and
``make results``, which records that JSON into the repository.

``make bench`` writes ``build/bench/figures.json`` (each module's figures with the commit,
time and machine it was measured on); ``make credibility`` writes one report JSON per plan
under ``runs/credibility/reports/``, stamped with its date and commit. ``make results``
(``python -m docsgen.results``) copies them into ``docs/results/``: the figures whole, each
report without its curves and paths (what the pages show, and the file names of its logs).
The pages then show those numbers and their stamps, and no number is typed by hand.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
from pathlib import Path
from typing import Any

from benchmarks.figures import Figure
from credibility.study import summary_markdown
from docsgen import RESULTS, prose, table_cell

FIGURES_FILE = "bench/figures.json"
REPORTS_DIR = "credibility"


# --- recording (make results) ---------------------------------------------------------------


def slim_report(report: dict[str, Any]) -> dict[str, Any]:
    """What the results page shows of a report: its stamps, plan, logs (by file name),
    summary and each test's index, without the curves, rows and machine paths."""
    plan = report["plan"]
    return {
        "package": report.get("package", ""),
        "package_version": report.get("package_version", ""),
        "created_utc": report.get("created_utc", ""),
        "commit": report.get("commit", ""),
        "plan": {
            "name": plan["name"],
            "file": Path(plan["path"]).name,
            "sha256": plan["sha256"],
            "description": plan.get("description", ""),
            "pass_mark": plan.get("pass_mark"),
            "eps_min": plan.get("eps_min"),
            "weights": plan.get("weights", {}),
        },
        "logs": [
            {
                "role": log["role"],
                "path": Path(log["path"]).name,
                "sha256": log["sha256"],
                "firmware": (log.get("provenance") or {}).get("firmware"),
            }
            for log in report["logs"]
        ],
        "summary": report["summary"],
        "tests": [
            {
                "name": test["name"],
                "kind": test["kind"],
                "eta": test.get("eta"),
                "passes_pass_mark": test.get("passes_pass_mark"),
                **({"not_scored": test["not_scored"]} if "not_scored" in test else {}),
            }
            for test in report.get("tests", [])
        ],
    }


def record(bench: Path | None, reports: Path | None, results: Path = RESULTS) -> list[Path]:
    """Copy the latest figures and reports into ``results``; return what was written.

    A source that does not exist leaves its recorded results as they are; a reports folder
    that holds reports replaces every recorded report (one no longer made goes away).
    """
    written = []
    if bench is not None and bench.is_file():
        target = results / FIGURES_FILE
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(bench, target)
        written.append(target)
    found = sorted(reports.glob("*/*.json")) if reports is not None and reports.is_dir() else []
    if found:
        folder = results / REPORTS_DIR
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        for path in found:
            target = folder / f"{path.parent.name}.json"
            report = json.loads(path.read_text(encoding="utf-8"))
            text = json.dumps(slim_report(report), indent=1, ensure_ascii=False) + "\n"
            target.write_text(text, encoding="utf-8")
            written.append(target)
    return written


# --- rendering ------------------------------------------------------------------------------

HOW_TO_RECORD = (
    "Record them with `make {target}` then `make results`, which copies the JSON into "
    "`docs/results/`; commit it, and `make docs` renders this page from it."
)


def benchmark_modules(root: Path = RESULTS.parent.parent) -> list[str]:
    """The benchmark modules ``make bench`` runs (``benchmarks/bench_*.py``)."""
    return sorted(path.stem for path in (root / "benchmarks").glob("bench_*.py"))


def render_speed(record: dict[str, Any] | None, expected: list[str] | None = None) -> str:
    """The speed page from a figures file: per benchmark module, its stamp and figures;
    the ``expected`` modules without figures are named, so a gap is not mistaken for a
    module that was left out."""
    lines = [
        "# Speed",
        "",
        "The figures of `make bench` (`python -m benchmarks`), as last recorded. Each "
        "module's figures carry the commit, the time and the machine they were measured on: "
        "on a shared machine a figure moves by tens of percent between minutes, so compare "
        "two records with `python -m benchmarks --compare OLD.json` rather than across "
        "pages. Nothing passes or fails on time; the goal column is the one the project set.",
        "",
    ]
    modules = (record or {}).get("modules", {})
    if not modules:
        lines += ["No speed figures have been recorded yet.", ""]
        lines += [HOW_TO_RECORD.format(target="bench"), ""]
        return "\n".join(lines)
    lines += [HOW_TO_RECORD.format(target="bench"), ""]
    missing = [name.removeprefix("bench_") for name in expected or [] if name not in modules]
    if missing:
        lines += [f"Not recorded yet: {', '.join(missing)} (`python -m benchmarks NAME`).", ""]
    for name, module in sorted(modules.items()):
        lines += [f"## {name.removeprefix('bench_')}", "", _bench_stamp(module), ""]
        lines += ["| figure | value | unit | goal | detail |", "|---|---:|---|---|---|"]
        for raw in module.get("figures", []):
            figure = Figure(**raw)
            value = "—" if math.isnan(figure.value) else figure.shown()
            lines.append(
                f"| {prose(table_cell(figure.name))} | {value} | {prose(table_cell(figure.unit))} "
                f"| {prose(table_cell(figure.goal))} | {prose(table_cell(figure.detail))} |"
            )
        lines.append("")
    return "\n".join(lines)


def _bench_stamp(module: dict[str, Any]) -> str:
    load, cpus = module.get("load_1min"), module.get("cpus")
    stamp = (
        f"Measured {module.get('measured', 'at an unrecorded time')} at commit "
        f"`{module.get('commit') or 'not recorded'}` on {cpus or '?'} CPUs"
        + (f", load {load} over the minute before." if load is not None else ".")
    )
    if load is not None and cpus and load > cpus:
        stamp += (
            f" **The machine was busy (load {load} on {cpus} CPUs): these figures understate "
            "what the code does on a quiet one.**"
        )
    return stamp


def render_credibility(reports: dict[str, dict[str, Any]]) -> str:
    """The credibility page from recorded reports: one summary table, then each report's
    stamp and tests."""
    lines = [
        "# Credibility",
        "",
        "The reports of `make credibility` (the [study](../tutorials/score-a-study.md)), as "
        "last recorded: the paper's indices per real log, what was scored and what was not, "
        "and why. η is the normalized credibility index of each test (1 is a perfect match); "
        "the paper calls a simulation credible when η_min ≥ ε_min.",
        "",
    ]
    if not reports:
        lines += ["No credibility results have been recorded yet.", ""]
        lines += [HOW_TO_RECORD.format(target="credibility"), ""]
        return "\n".join(lines)
    lines += [HOW_TO_RECORD.format(target="credibility"), ""]
    lines += ["## Summary", "", prose(summary_markdown(list(reports.values()))), ""]
    for key, report in reports.items():
        plan = report["plan"]
        lines += [f"## {plan['name']} {{ #{key.replace('_', '-')} }}", ""]
        lines += [_report_stamp(report), ""]
        logs = ", ".join(f"{log['role']} `{log['path']}`" + (f" ({log['firmware']})"
                         if log.get("firmware") else "") for log in report["logs"])  # fmt: skip
        lines += [f"Logs: {logs}.", ""]
        lines += ["| test | kind | η | at the pass mark |", "|---|---|---:|---|"]
        for test in report.get("tests", []):
            if "not_scored" in test:
                why = prose(table_cell(test["not_scored"].get("message", "")))
                lines.append(f"| {test['name']} | {test['kind']} | — | not scored: {why} |")
                continue
            passes = {True: "yes", False: "no"}.get(test.get("passes_pass_mark"), "")
            lines.append(
                f"| {test['name']} | {test['kind']} | {_eta(test.get('eta'))} | {passes} |"
            )
        lines.append("")
    return "\n".join(lines)


def _report_stamp(report: dict[str, Any]) -> str:
    plan = report["plan"]
    commit = report.get("commit") or "not recorded (the report predates the commit stamp)"
    return (
        f"Plan `{plan.get('file', plan.get('path', ''))}`; scored {report.get('created_utc', '?')}"
        f" at commit `{commit}` by {report.get('package', 'hil-rig credibility')} "
        f"{report.get('package_version', '')}."
    )


def _eta(value: float | None) -> str:
    return "—" if value is None else f"{value:.3f}"


def load_figures(results: Path = RESULTS) -> dict[str, Any] | None:
    """The recorded figures file, or None when none was recorded."""
    path = results / FIGURES_FILE
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None


def load_reports(results: Path = RESULTS) -> dict[str, dict[str, Any]]:
    """The recorded reports by their folder's name, in name order."""
    folder = results / REPORTS_DIR
    return {
        path.stem: json.loads(path.read_text(encoding="utf-8"))
        for path in sorted(folder.glob("*.json"))
    }


def main(argv: list[str] | None = None) -> int:
    """``make results``: record the latest figures and reports for the docs."""
    parser = argparse.ArgumentParser(
        prog="python -m docsgen.results",
        description="Copy make bench's figures and make credibility's reports into "
        "docs/results/, where make docs renders them.",
    )
    parser.add_argument("--bench", type=Path, default=Path("build/bench/figures.json"))
    parser.add_argument("--reports", type=Path, default=Path("runs/credibility/reports"))
    args = parser.parse_args(argv)
    written = record(args.bench, args.reports)
    for path in written:
        print(path)
    if not written:
        print(f"nothing to record: no {args.bench} and no reports under {args.reports}",
              file=sys.stderr)  # fmt: skip
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
