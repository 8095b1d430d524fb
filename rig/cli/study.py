"""``rig study LOG``: vehicle, replay, plan and report of one real flight, then the verdict."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

from rich.console import Console

from rig.cli.command import Command
from rig.cli.flight import run_with_progress
from rig.study import Study

#: Where a study goes without --out: one folder per log, so a second call resumes it.
STUDIES_DIR = Path("runs") / "study"


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", type=Path, help="the real flight's ULog")
    parser.add_argument("--vehicle", default=None, metavar="NAME|PATH",
                        help="vehicle file (default: the bundled one of the log's airframe, "
                             "else written from the log with --mass)")  # fmt: skip
    parser.add_argument("--mass", type=float, default=None, metavar="KG",
                        help="take-off mass: write the vehicle file from the log "
                             "(rig vehicle)")  # fmt: skip
    parser.add_argument("--px4", type=Path, default=None, metavar="DIR",
                        help="PX4 SITL build: PX4 replays the flight with the log's parameters "
                             "(default: the reference autopilot)")  # fmt: skip
    parser.add_argument("--out", type=Path, default=None,
                        help="study folder (default runs/study/<log name>); a study "
                             "interrupted there resumes")  # fmt: skip
    parser.add_argument("--instance", type=int, default=0, help="SITL instance i: ports +i")
    parser.add_argument("--force", action="store_true", help="start the study in --out over")


def _stage(console: Console, title: str, run: Callable[[], str | None]) -> None:
    """A stage's title, then what it did and how long it took (a kept stage says so)."""
    console.print(f"[bold]{title}[/]", highlight=False)
    started = time.monotonic()
    said = run() or "kept from the earlier run"
    console.print(f"    {said} ({time.monotonic() - started:.0f} s)", highlight=False,
                  soft_wrap=True)  # fmt: skip


def _study(args: argparse.Namespace, console: Console) -> int:
    """Progress on stderr, stage by stage; the verdict last, one line on stdout."""
    study = Study(args.log, args.out or STUDIES_DIR / args.log.stem, vehicle=args.vehicle,
                  mass_kg=args.mass, px4_dir=args.px4, instance=args.instance,
                  force=args.force)  # fmt: skip
    _stage(console, "1/4 vehicle", study.vehicle)
    _stage(console, "2/4 replay", lambda: run_with_progress(console, study.replay))
    _stage(console, "3/4 plan", study.plan)
    console.print("[bold]4/4 report[/]", highlight=False)
    verdict = study.report()
    print(f"study of {args.log.name}: {verdict.line()}")
    return verdict.exit_code


COMMAND = Command(
    "study",
    "one real flight log to a credibility verdict: vehicle, replay, automatic plan, report",
    "Study a PX4 multicopter log end to end: the vehicle (given, bundled for its airframe, "
    "or written from the log with --mass), the replay (PX4 SITL with the log's parameters "
    "with --px4, else the reference autopilot), the test plan found in the log, and the "
    "credibility report. Each stage is kept in the study folder, so an interrupted study "
    "resumes. Exit 0: pass; 1: fail (or an error, one line on stderr); 3: too few tests "
    "scored for a verdict.",
    _add_arguments,
    _study,
    interrupted="interrupted; run the same command again to resume the study",
    flies=True,
)
