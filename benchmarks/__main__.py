"""Run the benchmark modules (``benchmarks/bench_*.py``) and print one table of figures.

``python -m benchmarks`` runs them all; ``python -m benchmarks quad_model px4`` runs the
modules whose name contains one of the words. Whatever the tools print (Verilator builds,
cocotb, PX4's console) goes to ``build/bench/<module>.log``; the figures also go to
``build/bench/figures.json``, each module's with the commit, the time and the machine's
load it was measured at (a module not rerun keeps its last figures there).
``python -m benchmarks --compare BEFORE.json [AFTER.json]`` prints two such records side by
side (AFTER: ``build/bench/figures.json``), so two commits can be compared. Benchmarks
print numbers; they never pass or fail on time.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import json
import os
import pkgutil
import subprocess
import sys
import time
import traceback
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from benchmarks.figures import Figure

LOG_DIR = Path(__file__).resolve().parent.parent / "build" / "bench"
#: A figures file's modules: name → measured, commit, cpus, load_1min and figures.
Modules = dict[str, dict[str, Any]]


@contextlib.contextmanager
def _output_to(path: Path) -> Iterator[None]:
    """Send file descriptors 1 and 2 (this process's and every child's) to ``path``."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with path.open("w") as log:
        os.dup2(log.fileno(), 1)
        os.dup2(log.fileno(), 2)
        try:
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])


def _run(name: str, console: Console) -> list[Figure]:
    log_path = LOG_DIR / f"{name}.log"
    figures: list[Figure] = []
    started = time.monotonic()
    with console.status(f"{name} …"), _output_to(log_path):
        try:
            for figure in importlib.import_module(f"benchmarks.{name}").figures():
                figures.append(figure)
                print(f"{figure.name}: {figure.shown()} {figure.unit} {figure.detail}", flush=True)
        except Exception:  # a broken benchmark is a row of the table, not the end of the run
            traceback.print_exc()
            figures.append(Figure("did not finish", float("nan"), "", detail=f"see {log_path}"))
    console.print(f"{name}: {len(figures)} figures in {time.monotonic() - started:.0f} s")
    return figures


def main(argv: list[str]) -> int:
    if argv[:1] == ["--compare"]:
        return compare(argv[1:])
    names = sorted(
        m.name
        for m in pkgutil.iter_modules([str(Path(__file__).parent)])
        if m.name.startswith("bench_")
    )
    selected = [n for n in names if not argv or any(a in n for a in argv)]
    if not selected:
        print(f"no benchmark matches {argv}; available: {', '.join(names)}", file=sys.stderr)
        return 2
    LOG_DIR.mkdir(parents=True, exist_ok=True)
    # Wide enough for one line per figure when the table goes to a file or a CI log.
    console = Console(highlight=False, width=None if sys.stdout.isatty() else 220)
    results = {name: _run(name, console) for name in selected}

    table = Table(title="make bench (figures only: nothing passes or fails on time)")
    for heading, justify in (("benchmark", "left"), ("figure", "left"), ("value", "right"),
                             ("unit", "left"), ("goal", "left"), ("detail", "left")):  # fmt: skip
        table.add_column(heading, justify=justify, overflow="fold")
    for name, figures in results.items():
        for index, figure in enumerate(figures):
            table.add_row(
                name.removeprefix("bench_") if index == 0 else "",
                figure.name, figure.shown(), figure.unit, figure.goal, figure.detail,
                end_section=index == len(figures) - 1,
            )  # fmt: skip
    console.print(table)
    path = LOG_DIR / "figures.json"
    record = merged_record(_read_record(path) if path.is_file() else {}, results, _measured_at())
    path.write_text(json.dumps(record, indent=1, allow_nan=True) + "\n")
    console.print(f"tool output: {LOG_DIR}/<benchmark>.log; figures: {path}")
    return 0


def _measured_at() -> dict[str, object]:
    """When, on which commit and how loaded the machine was: what a figure depends on."""

    def git(*args: str) -> str:
        done = subprocess.run(["git", *args], cwd=LOG_DIR.parent.parent, capture_output=True,
                              text=True, check=False)  # fmt: skip
        return done.stdout.strip() if done.returncode == 0 else ""

    commit = git("rev-parse", "--short", "HEAD") or "unknown"
    if git("status", "--porcelain", "--untracked-files=no"):
        commit += " with uncommitted changes"
    return {
        "measured": datetime.now(UTC).isoformat(timespec="seconds"),
        "commit": commit,
        "cpus": os.cpu_count(),
        "load_1min": round(os.getloadavg()[0], 2),
    }


def merged_record(
    previous: Modules, results: dict[str, list[Figure]], measured_at: dict[str, object]
) -> dict[str, Modules]:
    """The figures file after a run: each module run now replaces its entry, the others
    keep theirs (``python -m benchmarks px4`` must not drop the quad_model figures)."""
    now = {name: {**measured_at, "figures": [dataclasses.asdict(f) for f in figs]}
           for name, figs in results.items()}  # fmt: skip
    return {"modules": {**previous, **now}}


def _read_record(path: Path) -> Modules:
    """The modules of a figures file; one written before the per-module entries had one
    ``measured`` for all (no commit)."""
    try:
        record = json.loads(path.read_text())
        if "modules" in record:
            return record["modules"]
        return {name: {"measured": record["measured"], "commit": "unknown", "figures": figures}
                for name, figures in record["figures"].items()}  # fmt: skip
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise SystemExit(f"benchmarks: {path}: not a figures file ({error})") from None


def compare(paths: list[str]) -> int:
    """Print BEFORE's and AFTER's figures side by side, with AFTER/BEFORE for each."""
    if not 1 <= len(paths) <= 2:
        print("usage: python -m benchmarks --compare BEFORE.json [AFTER.json]", file=sys.stderr)
        return 2
    before_path, after_path = Path(paths[0]), Path(paths[1] if len(paths) == 2 else
                                                   LOG_DIR / "figures.json")  # fmt: skip
    before, after = _read_record(before_path), _read_record(after_path)
    table = Table(title=f"{before_path} → {after_path}")
    for heading, justify in (("benchmark", "left"), ("figure", "left"), ("before", "right"),
                             ("after", "right"), ("after/before", "right"), ("unit", "left"),
                             ("goal", "left")):  # fmt: skip
        table.add_column(heading, justify=justify, overflow="fold")
    for name in sorted(set(before) | set(after)):
        old = {f["name"]: f for f in before.get(name, {}).get("figures", [])}
        new = {f["name"]: f for f in after.get(name, {}).get("figures", [])}
        for index, figure in enumerate(dict.fromkeys([*old, *new])):
            a, b = old.get(figure), new.get(figure)
            ratio = (
                "" if a is None or b is None or not a["value"] else f"{b['value'] / a['value']:.2f}"
            )
            table.add_row(
                name.removeprefix("bench_") if index == 0 else "", figure,
                _shown(a), _shown(b), ratio, (b or a)["unit"], (b or a)["goal"],
            )  # fmt: skip
        table.add_section()
    console = Console(highlight=False, width=None if sys.stdout.isatty() else 220)
    console.print(table)
    for label, modules in (("before", before), ("after", after)):
        commits = sorted({f"{m.get('commit', 'unknown')} ({m.get('measured', '?')})"
                          for m in modules.values()})  # fmt: skip
        console.print(f"{label}: {'; '.join(commits)}")
    return 0


def _shown(figure: dict[str, Any] | None) -> str:
    return "—" if figure is None else Figure(**figure).shown()


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
