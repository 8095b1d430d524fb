"""``rig identify LOG``: a vehicle's parameters from its flight log, as a table or as lines
for its vehicle file; or the IMU's noise and vibration (from PX4's IMU stream, or from the
raw FIFO at named windows); or the raw IMU tables, the log's and the model's."""

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
    FITTED_POINTS,
    LogVibration,
    fit_vibration,
    log_motor_drive,
    read_log_vibration,
    read_raw_imu,
    read_raw_vibration,
    supply_voltage,
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
                        help="write the log's raw IMU FIFO and the vehicle's IMU on the stand "
                             "driven by the log's motors, at the chip's rate, as "
                             "real_/sim_<gyro|accel>.parquet tables for a credibility plan, "
                             "instead")  # fmt: skip
    parser.add_argument("--at", nargs=3, action="append", default=[],
                        metavar=("NAME", "START", "END"),
                        help="with --vibration: fit the levels from the raw IMU FIFO at this "
                             "operating point (boot seconds; repeatable)")  # fmt: skip
    parser.add_argument("--rest", type=float, nargs=2, metavar=("START", "END"),
                        help="with --at: boot seconds the rotors are stopped (the IMU's white "
                             "noise)")  # fmt: skip
    parser.add_argument("--disarm", type=float, default=None, metavar="SECONDS",
                        help="with --raw-imu or --at, for a log without an arming topic: boot "
                             "seconds of its disarm (the ESCs get 0 from then)")  # fmt: skip
    parser.add_argument("--imu-hz", type=float, default=800.0,
                        help="the replay's IMU rate the vibration is fitted at (default 800, "
                             "PX4's lockstep at the X500's IMU_GYRO_RATEMAX)")  # fmt: skip


def _identify(args: argparse.Namespace, console: Console) -> int:
    """The table (or ``--toml`` lines) on stdout; the log is read once."""
    points = _points(args.at)
    if points and not args.vibration:
        raise IdentificationError("--at names the operating points of a --vibration fit")
    if args.rest and not points:
        raise IdentificationError("--rest names the rest of a raw --vibration fit: with --at")
    log = FlightLog.read(args.log)
    vehicle = load_vehicle(args.vehicle or vehicle_for_airframe(log.parameters, log.path))
    if args.raw_imu is not None:
        for path in write_raw_imu_tables(log, vehicle, args.raw_imu, args.disarm):
            print(path)
        return 0
    if args.vibration:
        if points:
            windows = ({"stopped": (args.rest[0], args.rest[1])} if args.rest else {}) | points
            measured: LogVibration = read_raw_vibration(
                log,
                read_raw_imu(log),
                log_motor_drive(log, vehicle, args.disarm),
                supply_voltage(log, vehicle),
                windows,
            )
            imu_hz = measured.stream_rate_hz
        else:
            measured, imu_hz = read_log_vibration(log), args.imu_hz
        fitted, _ = fit_vibration(vehicle, measured, imu_hz, tuple(points) or FITTED_POINTS)
        print(vibration_toml(fitted, measured, imu_hz), end="")
        return 0
    window = tuple(args.window) if args.window else None
    result = identify_vehicle(log, vehicle, window)
    if args.toml:
        print(identification_toml(result, vehicle), end="")
    else:
        Console(width=160).print(identification_table(result))
    return 0


def _points(given: list[list[str]]) -> dict[str, tuple[float, float]]:
    """``--at NAME START END`` as windows by name; bad seconds are one line."""
    points = {}
    for name, start, end in given:
        try:
            window = (float(start), float(end))
        except ValueError:
            raise IdentificationError(
                f"--at {name} {start} {end}: START and END are boot seconds"
            ) from None
        if name == "stopped" or not window[0] < window[1]:
            raise IdentificationError(
                f"--at {name} {start} {end}: a turning point needs its own name (--rest is "
                "the stopped one) and START before END"
            )
        points[name] = window
    return points


COMMAND = Command(
    "identify",
    "identify hover, roll/pitch plant and inertia from a flight log",
    "Estimate a vehicle's parameters from a PX4-style ULog, each with its uncertainty, method "
    "and window; --toml prints them as vehicle-file lines.",
    _add_arguments,
    _identify,
)
