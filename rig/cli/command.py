"""What a ``rig`` subcommand is: its name, its help and arguments, and the function that runs it."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass

from rich.console import Console


@dataclass(frozen=True)
class Command:
    """One ``rig`` subcommand; :func:`rig.cli.main` is the one error boundary around ``run``."""

    name: str
    #: One line in ``rig --help``.
    help: str
    #: A paragraph atop ``rig NAME --help``.
    description: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    #: Runs the parsed command; returns the exit status. Bad input raises (one line).
    run: Callable[[argparse.Namespace, Console], int]
    #: What Ctrl-C leaves behind, said on stderr.
    interrupted: str = "interrupted; the logs written so far are readable"
    #: A flight: SIGTERM is raised where the rig is, so every ``finally`` closes the logs and
    #: stops the autopilot (PX4 runs in its own session: a killed rig would leave it spinning).
    flies: bool = False
