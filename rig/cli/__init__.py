"""``rig``: the command line, one module per command, one error boundary (:func:`main`).

Errors are one line on stderr (exit 1); Ctrl-C stops a command cleanly with its logs
readable (exit 130), SIGTERM likewise during a flight (exit 143).
"""

from __future__ import annotations

import argparse
import signal
import sys

from rich.console import Console

from credibility import CredibilityError
from px4_logs import LogError
from quad_model.vehicle import VehicleFileError
from rig.cli import campaign, identify, plot, replay, run, schema, study, vehicle, view
from rig.cli.command import Command
from rig.errors import RigError

#: Every command, in the order ``rig --help`` lists them.
COMMANDS: tuple[Command, ...] = (
    run.RUN,
    run.HIL_SIM,
    replay.COMMAND,
    study.COMMAND,
    campaign.COMMAND,
    plot.COMMAND,
    view.COMMAND,
    identify.COMMAND,
    vehicle.COMMAND,
    schema.COMMAND,
)

#: ``rig --help``'s description and epilog: plain text, as a terminal shows them.
DESCRIPTION = """\
The hardware-in-the-loop rig: a 5 kHz multicopter model, emulated sensor chips and an
autopilot (the reference one, or PX4 SITL) flown in lockstep, with their logs."""
EPILOG = """\
examples:
  rig hil-sim --view                      the demo flight, watched in a browser
  rig run takeoff_hover_land              a bundled scenario (or a TOML path)
  rig run level_step --autopilot px4 --px4 DIR
  rig replay LOG.ulg                      a real flight through the rig
  rig vehicle LOG.ulg --mass 2.0          a vehicle file for the log's airframe
  rig study LOG.ulg --px4 DIR             a real flight to a credibility verdict
  rig campaign motor_faults               a fault-injection campaign
  rig schema --out schemas                the configuration files' JSON Schema

Errors are one line on stderr (exit 1); Ctrl-C stops a run cleanly with its logs
readable (exit 130; SIGTERM 143). `rig COMMAND --help` details each command."""


class Terminated(BaseException):
    """SIGTERM during a flight, raised where the rig is (see :attr:`Command.flies`)."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated


def build_parser() -> argparse.ArgumentParser:
    """The ``rig`` parser with every command's sub-parser (also the CLI reference's source)."""
    parser = argparse.ArgumentParser(
        prog="rig",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        sub = commands.add_parser(command.name, help=command.help,
                                  description=command.description)  # fmt: skip
        command.add_arguments(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one command; every error it raises ends here as one line."""
    args = build_parser().parse_args(argv)
    command = next(c for c in COMMANDS if c.name == args.command)
    if command.flies:
        signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        return command.run(args, Console(stderr=True))
    except (RigError, LogError, VehicleFileError, CredibilityError) as error:
        print(f"rig: error: {error}", file=sys.stderr)  # one line, never wrapped
        return 1
    except KeyboardInterrupt:
        print(f"rig: {command.interrupted}", file=sys.stderr)
        return 130
    except Terminated:
        print("rig: terminated (SIGTERM); the logs written so far are readable", file=sys.stderr)
        return 143
