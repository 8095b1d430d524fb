"""Run the benchmark modules (``benchmarks/bench_*.py``) and print one table of figures.

``python -m benchmarks`` runs them all; ``python -m benchmarks quad_model px4`` runs the
modules whose name contains one of the words. Whatever the tools print (Verilator builds,
cocotb, PX4's console) goes to ``build/bench/<module>.log``; the figures also go to
``build/bench/figures.json``. Benchmarks print numbers; they never pass or fail on time.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import json
import os
import pkgutil
import sys
import time
import traceback
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path

from rich.console import Console
from rich.table import Table

from benchmarks.figures import Figure

LOG_DIR = Path(__file__).resolve().parent.parent / "build" / "bench"


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
    record = {
        "measured": datetime.now(UTC).isoformat(timespec="seconds"),
        "figures": {name: [dataclasses.asdict(f) for f in figs] for name, figs in results.items()},
    }
    (LOG_DIR / "figures.json").write_text(json.dumps(record, indent=1, allow_nan=True) + "\n")
    console.print(f"tool output: {LOG_DIR}/<benchmark>.log; figures: {LOG_DIR}/figures.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
