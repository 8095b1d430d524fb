"""``credibility`` command line: ``report PLAN.toml``, ``plan LOG``, ``summary REPORT.json ...``
and ``paper``.

Exit codes: 0 when η_min ≥ ε_min, 1 when not, 2 for bad input or usage (one line on
stderr), 3 when the inputs were read but too few tests could be scored for a verdict.
"""

import argparse
import contextlib
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from credibility.assess import assess, steps
from credibility.autoplan import write_plan
from credibility.errors import CredibilityError
from credibility.indices import KINDS
from credibility.paper import paper_comparison
from credibility.plan import load_plan, with_weights
from credibility.report import ExitCode, exit_code, write_report
from credibility.study import read_report, summary_markdown
from px4_logs import FlightLog, LogError

#: ``credibility report --help`` ends with what each exit code means.
EXIT_CODES = """exit codes:
  0  pass: η_min ≥ ε_min over the scored tests
  1  fail: η_min < ε_min (a result, not an error)
  2  bad input: the plan or a log cannot be read, or a wrong option; nothing is written
  3  could not be scored: the logs were read, but a kind of test kept fewer than half of
     its tests (a topic missing, a log too short, ε undefined); the report says which

Every test is scored or listed as not scored with its reason; the report's warnings
(HTML and JSON) also name sample rates and sample counts that bias a statistic, and
thresholds below the real log's noise."""


class _Parser(argparse.ArgumentParser):
    """argparse that exits with the package's bad-input code and a one-line message."""

    def error(self, message: str) -> NoReturn:
        self.exit(ExitCode.BAD_INPUT, f"credibility: error: {message}\n")


def _log_override(text: str) -> tuple[str, Path]:
    role, sep, path = text.partition("=")
    if not sep or not role or not path:
        raise argparse.ArgumentTypeError(f"--log expects ROLE=PATH, got {text!r}")
    return role, Path(path)


def _weight_list(text: str) -> dict[str, float]:
    parts = text.split(",")
    try:
        values = [float(part) for part in parts]
    except ValueError:
        values = []
    if len(values) != len(KINDS):
        raise argparse.ArgumentTypeError(
            f"expects {len(KINDS)} numbers ({','.join(KINDS)}), got {text!r}"
        )
    return dict(zip(KINDS, values, strict=True))


def _weight_item(text: str) -> tuple[str, float]:
    kind, sep, value = text.partition("=")
    if sep and kind:
        with contextlib.suppress(ValueError):
            return kind, float(value)
    raise argparse.ArgumentTypeError(f"expects KIND=NUMBER, got {text!r}")


def _weights_source(args: argparse.Namespace) -> str:
    """The weight options as the user gave them, for the report's note."""
    given = [f"--weight {kind}={value:g}" for kind, value in args.weight]
    if args.weights:
        given.insert(0, "--weights " + ",".join(f"{v:g}" for v in args.weights.values()))
    return "command line " + " ".join(given)


#: ``credibility --help``'s description: plain text, as a terminal shows it.
DESCRIPTION = """\
Score how far a simulation can be trusted against recorded real flights, with the
normalized credibility indices of Dai, Ke, Quan and Cai: logs in (ULog, CSV, Parquet),
an HTML and a JSON report out."""
EPILOG = """\
examples:
  credibility report credibility/plans/quad4001_repeatability.toml --out out/
  credibility report PLAN.toml --log sim=runs/RUN/rig.ulg
  credibility plan flight.ulg --sim runs/RUN/px4.ulg --out flight_plan.toml
  credibility summary out/*/*.json --out summary.md
  credibility paper

`credibility report --help` lists the exit codes."""


def build_parser() -> argparse.ArgumentParser:
    """The ``credibility`` command line, apart from running it: the docs' CLI reference reads it."""
    parser = _Parser(
        prog="credibility",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", required=True)
    report = commands.add_parser(
        "report",
        help="score logs with a test plan",
        description="Score logs with a test plan; write <plan>.html and <plan>.json.",
        epilog=EXIT_CODES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    report.add_argument("plan", type=Path, help="test plan (TOML)")
    report.add_argument(
        "--log",
        action="append",
        type=_log_override,
        default=[],
        metavar="ROLE=PATH",
        help="replace the log of a role named in the plan (repeatable)",
    )
    report.add_argument(
        "--weights",
        type=_weight_list,
        metavar="P,T,F",
        help="η_all weights for performance, time, frequency, replacing the plan's "
        "[weights]; relative, normalized to sum 1",
    )
    report.add_argument(
        "--weight",
        action="append",
        type=_weight_item,
        default=[],
        metavar="KIND=NUMBER",
        help="replace one kind's η_all weight (repeatable, after --weights); then normalized",
    )
    report.add_argument("--out", type=Path, default=Path("."), help="output directory")
    summary = commands.add_parser(
        "summary",
        help="one table over several reports: per real log, what was scored and what not, why",
        description="One Markdown table over several reports' JSON: per real log, the outcome, "
        "the indices, the tests scored and those its log cannot support, with the reason.",
    )
    summary.add_argument("reports", type=Path, nargs="+", help="reports' JSON (report --out)")
    summary.add_argument("--out", type=Path, default=None, help="also write it here (Markdown)")
    plan = commands.add_parser(
        "plan",
        help="find the segments the paper's tests need in a real PX4 log; write a plan",
        description="Find in a real PX4 log the segments the paper's tests need (rest, idle "
        "and hover noise, set-point steps, the pilot's inputs for frequency responses) and "
        "write a test plan to edit and score; every test the log cannot support is listed "
        "in it as [[not_scorable]] with the reason.",
    )
    plan.add_argument("log", type=Path, help="the real flight's ULog")
    plan.add_argument(
        "--sim",
        type=Path,
        default=None,
        help="the simulation log to score (default: a placeholder to replace in [logs])",
    )
    plan.add_argument(
        "--out", type=Path, default=None, help="plan file to write (default: <log>_plan.toml)"
    )
    commands.add_parser(
        "paper",
        help="recompute the paper's tables beside its printed numbers",
        description="Recompute every figure of the paper's section 4 from the errors and "
        "thresholds it prints, beside the printed numbers, with the mismatches explained.",
    )
    return parser


def _report(args: argparse.Namespace, console: Console) -> int:
    plan = load_plan(args.plan, dict(args.log))
    for role, path in sorted(dict(args.log).items()):
        console.print(f"log {role} = {path}")
    overrides = (args.weights or {}) | dict(args.weight)
    if overrides:
        plan = with_weights(plan, overrides, _weights_source(args))
        shares = ", ".join(f"{kind} {alpha:.3g}" for kind, alpha in plan.weights.items())
        console.print(f"weights: {shares} ({plan.weights_source})")
    columns = (TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn())
    # Progress only on a terminal: a pipeline's stderr gets the result lines alone.
    live = console.is_terminal
    with Progress(*columns, console=console, transient=True, disable=not live) as progress:
        task = progress.add_task("scoring", total=steps(plan))

        def advance(label: str) -> None:
            progress.update(task, description=label)
            progress.advance(task)

        assessment = assess(plan, advance, strict=False)
    for caveat in assessment.caveats:
        test = f"{caveat.test}: " if caveat.test else ""
        console.print(f"[yellow]warning:[/] {escape(f'{test}{caveat.kind}: {caveat.message}')}")
    html_path, json_path = write_report(assessment, args.out)
    code = exit_code(assessment)
    if assessment.not_scored:
        console.print(
            f"{len(assessment.not_scored)} of {len(plan.tests)} tests not scored: "
            + ", ".join(item.test.name for item in assessment.not_scored)
        )
    for item in plan.not_scorable:
        console.print(
            f"not scorable from these logs: {item.name} ({item.kind}): {item.reason}", markup=False
        )
    if code == ExitCode.NOT_SCORED:
        verdict = f"could not be scored: {assessment.unscorable_reason}"
    else:
        verdict = (
            f"η_all {assessment.eta_all:.2%}, η_min {assessment.eta_min:.2%} "
            f"{'≥' if code == ExitCode.PASS else '<'} ε_min {plan.eps_min:.0%}"
        )
    console.print(f"{verdict} → {html_path}, {json_path}")
    return code


def _paper(console: Console) -> int:
    table = Table(title="Dai et al., section 4: printed vs recomputed (K_e = 0.75)")
    for column in ("section", "figure", "inputs", "printed %", "recomputed %", "status"):
        table.add_column(column)
    notes: list[str] = []
    for fig in paper_comparison():
        style = {"match": "green", "within rounding": "yellow", "mismatch": "red"}[fig.status]
        status = f"[{style}]{fig.status}[/]"
        if fig.note:
            notes.append(f"[{len(notes) + 1}] {fig.label}: {fig.note}")
            status += f" \\[{len(notes)}]"
        table.add_row(
            fig.section,
            fig.label,
            fig.inputs,
            f"{fig.printed_pct:g}",
            f"{fig.recomputed_pct:.2f}",
            status,
        )
    console.print(table)
    for note in notes:
        console.print(note, markup=False)
    return 0


def _summary(args: argparse.Namespace) -> int:
    text = summary_markdown([read_report(path) for path in args.reports])
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text, encoding="utf-8")
    print(text, end="")
    return 0


def _plan(args: argparse.Namespace) -> int:
    out = args.out or Path(f"{args.log.stem}_plan.toml")
    try:
        log = FlightLog.read(args.log)
    except LogError as error:
        raise CredibilityError(str(error)) from None
    draft = write_plan(log, out, args.sim)
    print(f"{len(draft.tests)} tests planned, {len(draft.not_scorable)} not scorable → {out}")
    for item in draft.not_scorable:
        print(f"not scorable: {item.name} ({item.kind}): {item.reason}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # A pipe gets 80 columns from rich; the paper table needs about 130.
    out = Console(highlight=False, width=None if sys.stdout.isatty() else 130)
    err = Console(stderr=True, highlight=False, soft_wrap=True)  # one message, one line
    try:
        if args.command == "paper":
            return _paper(out)
        if args.command == "summary":
            return _summary(args)
        if args.command == "plan":
            return _plan(args)
        return _report(args, err)
    except CredibilityError as exc:
        print(f"credibility: error: {exc}", file=sys.stderr)
        return ExitCode.BAD_INPUT


if __name__ == "__main__":
    raise SystemExit(main())
