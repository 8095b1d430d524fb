"""``rig vehicle LOG --mass KG``: a complete vehicle file for the airframe that flew a log,
every value tagged with its source (the log, ``rig identify``'s fits, the generic multicopter
of that mass)."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from rich.console import Console

from px4_logs import FlightLog
from rig.cli.command import Command
from rig.identify import IdentificationError
from rig.identify.vehicle_file import vehicle_from_log


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", type=Path, help="PX4 ULog of the vehicle (a flight with a hover)")
    parser.add_argument("--mass", type=float, default=None, metavar="KG",
                        help="the take-off mass, required (a log holds no weight)")  # fmt: skip
    parser.add_argument("--window", type=float, nargs=2, metavar=("START", "END"),
                        help="boot seconds of a manual roll/pitch excitation: the inertia and "
                             "motor lag are fitted there (default: not fitted)")  # fmt: skip
    parser.add_argument("--out", type=Path, default=None, metavar="FILE",
                        help="write the vehicle file here and print a summary per table "
                             "(default: the file on stdout)")  # fmt: skip


def _vehicle(args: argparse.Namespace, console: Console) -> int:
    """The file on stdout, or written to ``--out`` with one summary line per table."""
    if args.mass is None:  # here, not argparse's required: its error is the usage, two lines
        raise IdentificationError(f"{args.log}: --mass KG is required (a log holds no weight)")
    command = ["rig", "vehicle", args.log.name, "--mass", f"{args.mass:g}"]
    window = tuple(args.window) if args.window else None
    if window:
        command += ["--window", *(f"{t:g}" for t in window)]
    if args.out is not None:
        command += ["--out", args.out.name]
    result = vehicle_from_log(FlightLog.read(args.log), args.mass, shlex.join(command), window)
    if args.out is None:
        print(result.toml(), end="")
        return 0
    args.out.write_text(result.toml(), encoding="utf-8")
    print(f"{args.out}: {result.vehicle.name}")
    for line in result.summary():
        print(f"  {line}")
    return 0


COMMAND = Command(
    "vehicle",
    "write a vehicle file for the airframe of a flight log",
    "Write a complete vehicle file from a PX4-style ULog and the vehicle's mass: the rotor "
    "geometry and pack from the log's parameters, the hover, thrust coefficient, battery and "
    "IMU fitted as `rig identify` does, the rest from a generic multicopter of that mass; "
    "every value tagged [log], [identified], [default] or [given], with its ±.",
    _add_arguments,
    _vehicle,
)
