"""``rig replay LOG``: fly a real PX4 flight log through the rig."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from rig.cli.command import Command
from rig.cli.flight import add_run_options, announce, fly, run_options
from rig.replay import Drive, ReplayOptions, plan_replay, run_replay
from rig.scenarios.scenario import Rates


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", type=Path, help="the real flight's ULog")
    parser.add_argument("--drive", type=Drive, choices=list(Drive), default=Drive.VELOCITY,
                        help="which of the log's setpoints drive the autopilot")  # fmt: skip
    parser.add_argument("--window", type=float, nargs=2, metavar=("START", "END"), default=None,
                        help="boot seconds where --drive attitude|rates acts")  # fmt: skip
    parser.add_argument("--start", type=float, default=None,
                        help="boot seconds, landed (default: log start)")  # fmt: skip
    parser.add_argument("--end", type=float, default=None,
                        help="boot seconds (default: the log's last timestamp)")  # fmt: skip
    parser.add_argument("--vehicle", default=None, metavar="NAME|PATH",
                        help="vehicle file (default: from the log's SYS_AUTOSTART)")  # fmt: skip
    parser.add_argument("--seed", type=int, default=0, help="seed of every random source")
    parser.add_argument(
        "--imu-hz",
        type=int,
        default=None,
        help=f"IMU rate = lockstep rate (default {Rates().imu_hz}; with PX4 the log's "
        "IMU_GYRO_RATEMAX)",
    )
    add_run_options(parser, scenario=False)


def _replay(args: argparse.Namespace, console: Console) -> int:
    """The plan first (a bad log fails before anything starts), then the run."""
    given = {"sensor_layer": args.sensor_layer, "imu_hz": args.imu_hz}
    replay_options = ReplayOptions(
        drive=args.drive, window_s=tuple(args.window) if args.window else None,
        start_s=args.start, end_s=args.end, vehicle=args.vehicle, seed=args.seed,
        autopilot=args.autopilot, px4_dir=args.px4,
        **{name: value for name, value in given.items() if value is not None},
    )  # fmt: skip
    plan = plan_replay(args.log, replay_options)
    options = run_options(args)
    how = "as its pilot flew it" if plan.px4 else f"{plan.drive} drive"
    name = f"replay of {plan.log_path.name}"
    announce(console, name,
             f"{how}, {plan.start_s:.3f}-{plan.end_s:.3f} s, vehicle "
             f"{plan.vehicle} ({plan.vehicle_reason}), {len(plan.parameters)} parameters "
             f"from the log", replay_options.sensor_layer, options)  # fmt: skip
    for level, text in plan.notes:
        console.print(f"{level}: {text}", highlight=False)
    return fly(args, console, name, lambda p: run_replay(plan, options, p))


COMMAND = Command(
    "replay",
    "fly a real PX4 flight log through the rig: its setpoints (reference autopilot) or, with "
    "PX4, its parameters, sticks, modes and mission",
    "Replay a real PX4 flight on the log's own clock: the reference autopilot flies its "
    "set-points, or PX4 SITL (--autopilot px4) flies it as its pilot did, with the log's "
    "parameters, sticks, modes and mission. replay.json says what was applied.",
    _add_arguments,
    _replay,
    flies=True,
)
