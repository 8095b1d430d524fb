"""``rig run SCENARIO`` and ``rig hil-sim``: fly a scenario closed loop."""

from __future__ import annotations

import argparse
import dataclasses

from rich.console import Console

from rig.cli.command import Command
from rig.cli.flight import add_run_options, announce, fly, run_options
from rig.lockstep.loop import run_scenario
from rig.scenarios.scenario import load_scenario

HIL_SIM_SCENARIO = "hil_sim"


def _add_scenario(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", help="path to a scenario TOML, or a name in rig/scenarios/")
    add_run_options(parser)


def _run(args: argparse.Namespace, console: Console) -> int:
    scenario = load_scenario(HIL_SIM_SCENARIO if args.command == "hil-sim" else args.scenario)
    if args.vehicle is not None:
        scenario = dataclasses.replace(scenario, vehicle=args.vehicle)
    options = dataclasses.replace(
        run_options(args),
        on_waiting=lambda command: console.print(
            f"waiting for PX4; start it with:\n  {command}", highlight=False, soft_wrap=True
        ),
    )
    announce(console, scenario.name, scenario.description,
             options.sensor_layer or scenario.sensor_layer, options)  # fmt: skip
    return fly(args, console, scenario.name, lambda p: run_scenario(scenario, options, p))


RUN = Command(
    "run",
    "fly a scenario file (or a bundled scenario name)",
    "Fly a scenario closed-loop: the model, the sensor chips and the autopilot in lockstep. "
    "The run folder gets rig.ulg, the autopilot's log and PNG plots.",
    _add_scenario,
    _run,
    flies=True,
)
HIL_SIM = Command(
    "hil-sim",
    "the demo flight: take off, hover, step, land with RTL sensors and the reference autopilot",
    "The demo flight (scenario hil_sim): take off to 5 m, hover, a 5 m level step, land, on "
    "the RTL chips, at most at real time so that it can be watched.",
    add_run_options,
    _run,
    flies=True,
)
