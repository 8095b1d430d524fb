"""``rig plot RUN``: remake the plots of a finished run."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from rig.cli.command import Command
from rig.cli.flight import plot_names
from rig.plots import plot_run


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", type=Path, help="the run folder (holds rig.ulg)")


def _plot(args: argparse.Namespace, console: Console) -> int:
    console.print(f"plots: {plot_names(plot_run(args.run))}", highlight=False, soft_wrap=True)
    return 0


COMMAND = Command(
    "plot",
    "(re)make a finished run's PNG plots in its folder",
    "Remake position.png, attitude.png, motors.png and imu_psd.png of a run.",
    _add_arguments,
    _plot,
)
