"""``rig identify LOG``: a vehicle's parameters from its flight log, as a table or as lines
for its vehicle file; or the IMU's noise and vibration; or the raw IMU tables of a rest."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from px4_logs import FlightLog
from quad_model.vehicle import load_vehicle, vehicle_for_airframe
from rig.cli.command import Command
from rig.identify import (
    IdentificationError,
    identification_table,
    identification_toml,
    identify_vehicle,
)
from rig.identify.vibration import (
    fit_vibration,
    read_log_vibration,
    vibration_toml,
    write_raw_imu_tables,
)


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", type=Path, help="PX4-style ULog (real flight, SITL or rig)")
    parser.add_argument("--vehicle", default=None, metavar="NAME|PATH",
                        help="vehicle file (default: from the log's SYS_AUTOSTART)")  # fmt: skip
    parser.add_argument("--window", type=float, nargs=2, metavar=("START", "END"),
                        help="boot seconds of the rate-loop fit (default: airborne)")  # fmt: skip
    parser.add_argument("--toml", action="store_true",
                        help="print [body]/[propulsion] lines for the vehicle file")  # fmt: skip
    parser.add_argument("--vibration", action="store_true",
                        help="fit the IMU noise and the vibration per operating point instead "
                             "and print [imu]/[vibration] lines")  # fmt: skip
    parser.add_argument("--raw-imu", type=Path, default=None, metavar="DIR",
                        help="write the log's raw IMU FIFO and the vehicle's IMU model at rest "
                             "(--rest) at the chip's rate as real_/sim_<gyro|accel>.parquet "
                             "tables for a credibility plan, instead")  # fmt: skip
    parser.add_argument("--rest", type=float, nargs=2, metavar=("START", "END"),
                        help="with --raw-imu: boot seconds the rotors are stopped")  # fmt: skip
    parser.add_argument("--imu-hz", type=float, default=800.0,
                        help="the replay's IMU rate the vibration is fitted at (default 800, "
                             "PX4's lockstep at the X500's IMU_GYRO_RATEMAX)")  # fmt: skip


def _identify(args: argparse.Namespace, console: Console) -> int:
    """The table (or ``--toml`` lines) on stdout; the log is read once."""
    if args.raw_imu is not None and args.rest is None:
        raise IdentificationError("--raw-imu needs --rest START END")
    log = FlightLog.read(args.log)
    vehicle = load_vehicle(args.vehicle or vehicle_for_airframe(log.parameters, log.path))
    if args.raw_imu is not None:
        for path in write_raw_imu_tables(log, vehicle, tuple(args.rest), args.raw_imu):
            print(path)
        return 0
    if args.vibration:
        measured = read_log_vibration(log)
        fitted, _ = fit_vibration(vehicle, measured, args.imu_hz)
        print(vibration_toml(fitted, measured, args.imu_hz), end="")
        return 0
    window = tuple(args.window) if args.window else None
    result = identify_vehicle(log, vehicle, window)
    if args.toml:
        print(identification_toml(result, vehicle), end="")
    else:
        Console(width=160).print(identification_table(result))
    return 0


COMMAND = Command(
    "identify",
    "identify hover, roll/pitch plant and inertia from a flight log",
    "Estimate a vehicle's parameters from a PX4-style ULog, each with its uncertainty, method "
    "and window; --toml prints them as vehicle-file lines.",
    _add_arguments,
    _identify,
)
