"""One table over several reports (``credibility summary REPORT.json ...``): per real log, what
was scored and what was not and why, as ``make credibility`` prints it after the study.

It reads the reports' JSON (:func:`credibility.report.to_dict`), so it says exactly what they
say: the indices, each test not scored with its reason, and each test its plan declares not
scorable from that log (``[[not_scorable]]``) with the plan's reason.
"""

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from credibility.errors import CredibilityError
from credibility.indices import KINDS

#: What the table reads from each report's summary (``not_scorable`` is optional: older
#: reports had none declared).
SUMMARY_KEYS = frozenset(
    {"outcome", "exit_code", "scored", "tests", "eta_all", "eta_min", "means", "not_scored",
     "unscorable_reason"}
)  # fmt: skip


def read_report(path: Path) -> dict[str, Any]:
    """A report's JSON; anything else is one line naming the file."""
    try:
        report = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise CredibilityError(f"{path}: not a readable credibility report ({error})") from None
    if not isinstance(report, dict) or not {"plan", "summary", "logs"} <= report.keys():
        raise CredibilityError(f"{path}: not a credibility report (no plan, summary and logs)")
    missing = sorted(SUMMARY_KEYS - report["summary"].keys())
    if missing:
        raise CredibilityError(
            f"{path}: the report's summary has no {', '.join(missing)} (written by an older "
            "credibility: report it again)"
        )
    return report


def _real_logs(report: dict[str, Any]) -> str:
    """What a report scored against, by file name: its roles named real* (a real flight's
    log, or tables made from one) or, in a plan of two models, its reference."""
    names = {
        Path(log["path"]).name
        for log in report["logs"]
        if log["role"].startswith("real") or log["role"] == "reference"
    }
    return ", ".join(sorted(names)) or "(no real or reference role)"


def _pct(value: float | None) -> str:
    return "—" if value is None else f"{value:.1%}"


def summary_markdown(reports: Sequence[dict[str, Any]]) -> str:
    """The per-log table, then per log the tests not scored and not scorable, with reasons."""
    lines = [
        "| real log | plan | outcome | scored | η_all | η_min | "
        + " | ".join(f"η̄_{kind[0]}" for kind in KINDS)
        + " | not scored | not scorable |",
        "|" + "---|" * (8 + len(KINDS)),
    ]
    for report in reports:
        summary = report["summary"]
        means = summary["means"]
        lines.append(
            f"| {_real_logs(report)} | {report['plan']['name']} | {summary['outcome']} "
            f"(exit {summary['exit_code']}) | {summary['scored']} of {summary['tests']} | "
            f"{_pct(summary['eta_all'])} | {_pct(summary['eta_min'])} | "
            + " | ".join(_pct(means.get(kind)) for kind in KINDS)
            + f" | {len(summary['not_scored'])} | {len(summary.get('not_scorable', []))} |"
        )
    for report in reports:
        summary = report["summary"]
        lines += ["", f"**{_real_logs(report)}** ({report['plan']['name']})", ""]
        if summary["unscorable_reason"]:
            lines.append(f"- could not be scored: {summary['unscorable_reason']}")
        reasons = {
            test["name"]: test["not_scored"]["message"]
            for test in report.get("tests", [])
            if "not_scored" in test
        }
        lines += [
            f"- not scored: {name}: {reasons.get(name, '')}" for name in summary["not_scored"]
        ]
        lines += [
            f"- not scorable ({item['kind']}): {item['name']}: {item['reason']}"
            for item in summary.get("not_scorable", [])
        ]
        if not summary["not_scored"] and not summary.get("not_scorable"):
            lines.append("- every test the plan names was scored")
    return "\n".join(lines) + "\n"
