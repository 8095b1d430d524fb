"""``rig``: run scenarios closed-loop (``rig run``), the demo flight (``rig hil-sim``),
replays of real flights (``rig replay``), campaigns of many runs (``rig campaign``), a run's
plots (``rig plot``), a run in the browser (``--view`` while it flies, ``rig view`` after),
identification from a log (``rig identify``) and the configuration files' JSON Schema
(``rig schema``).

Errors are one line on stderr (exit 1); Ctrl-C stops the run cleanly with the logs
readable (exit 130).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

from rich.console import Console
from rich.live import Live
from rich.text import Text

from rig.apps.plots import plot_run
from rig.apps.replay import DRIVES, ReplayOptions, plan_replay, run_replay
from rig.apps.schemas import write_schemas
from rig.apps.view import VIEW_PORT, ViewError, ViewServer, load_recording
from rig.errors import RigError
from rig.lockstep.loop import AUTOPILOTS, RUNS_DIR, Progress, RunOptions, RunResult, run_scenario
from rig.lockstep.pacing import parse_speed
from rig.mavlink.px4_api import Ports
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import Rates, SensorLayer, load_scenario

HIL_SIM_SCENARIO = "hil_sim"
#: Pacing per command: the demo flight is watched in a ground station, so real time.
DEFAULT_SPEED = {"hil-sim": 1.0}


class Terminated(BaseException):
    """SIGTERM, raised where the rig is, so every ``finally`` closes the logs and stops the
    autopilot (PX4 runs in its own session: a killed rig would leave it spinning)."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated


def _speed(text: str) -> float:
    try:
        return parse_speed(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


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
  rig campaign motor_faults               a fault-injection campaign
  rig schema --out schemas                the configuration files' JSON Schema

Errors are one line on stderr (exit 1); Ctrl-C stops a run cleanly with its logs
readable (exit 130; SIGTERM 143). `rig COMMAND --help` details each command."""


def build_parser() -> argparse.ArgumentParser:
    """The ``rig`` command line, apart from running it: the docs' CLI reference reads it."""
    parser = argparse.ArgumentParser(
        prog="rig",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser(
        "run",
        help="fly a scenario file (or a bundled scenario name)",
        description="Fly a scenario closed-loop: the model, the sensor chips and the autopilot "
        "in lockstep. The run folder gets rig.ulg, the autopilot's log and PNG plots.",
    )
    run.add_argument("scenario", help="path to a scenario TOML, or a name in rig/scenarios/")
    _add_run_options(run)
    demo = commands.add_parser(
        "hil-sim",
        help="take off, hover, step, land with RTL sensors and the reference autopilot",
        description="The demo flight (scenario hil_sim): take off to 5 m, hover, a 5 m level "
        "step, land, on the RTL chips, at most at real time so that it can be watched.",
    )
    _add_run_options(demo)
    replay = commands.add_parser(
        "replay",
        help="fly a real PX4 flight log through the rig: its setpoints (reference autopilot) "
        "or, with PX4, its parameters, sticks, modes and mission",
        description="Replay a real PX4 flight on the log's own clock: the reference autopilot "
        "flies its set-points, or PX4 SITL (--autopilot px4) flies it as its pilot did, with the "
        "log's parameters, sticks, modes and mission. replay.json says what was applied.",
    )
    replay.add_argument("log", type=Path, help="the real flight's ULog")
    replay.add_argument("--drive", choices=DRIVES, default="velocity",
                        help="which of the log's setpoints drive the autopilot")  # fmt: skip
    replay.add_argument("--window", type=float, nargs=2, metavar=("START", "END"), default=None,
                        help="boot seconds where --drive attitude|rates acts")  # fmt: skip
    replay.add_argument("--start", type=float, default=None,
                        help="boot seconds, landed (default: log start)")  # fmt: skip
    replay.add_argument("--end", type=float, default=None,
                        help="boot seconds (default: the log's last timestamp)")  # fmt: skip
    replay.add_argument("--vehicle", default=None, metavar="NAME|PATH",
                        help="vehicle file (default: from the log's SYS_AUTOSTART)")  # fmt: skip
    replay.add_argument("--seed", type=int, default=0, help="seed of every random source")
    replay.add_argument(
        "--imu-hz",
        type=int,
        default=None,
        help=f"IMU rate = lockstep rate (default {Rates().imu_hz}; with PX4 the log's "
        "IMU_GYRO_RATEMAX)",
    )
    _add_run_options(replay, scenario=False)
    campaign = commands.add_parser(
        "campaign",
        help="run a campaign file (resumable), or `campaign report DIR`",
        description="Fly every case of a campaign (a base scenario swept over axes) as a rig "
        "run, locally or on a Dask cluster; rerun to resume. 'rig campaign report DIR' remakes "
        "the report of a results folder.",
    )
    campaign.add_argument("campaign", help="campaign TOML (or bundled name), or 'report'")
    campaign.add_argument("folder", nargs="?", type=Path, help="with 'report': the results folder")
    campaign.add_argument(
        "--out",
        type=Path,
        default=None,
        help="results folder (default runs/campaign-<name>; reruns resume)",
    )
    campaign.add_argument("--workers", type=int, default=None,
                          help="local processes (default: the cores given)")  # fmt: skip
    campaign.add_argument("--scheduler", default=None, metavar="tcp://HOST:8786",
                          help="run on this Dask cluster instead of local processes")  # fmt: skip
    plot = commands.add_parser(
        "plot",
        help="(re)make a finished run's PNG plots in its folder",
        description="Remake position.png, attitude.png, motors.png and imu_psd.png of a run.",
    )
    plot.add_argument("run", type=Path, help="the run folder (holds rig.ulg)")
    view = commands.add_parser(
        "view",
        help="play a finished run back in the browser",
        description="Serve a finished run's playback on 127.0.0.1 until Ctrl-C.",
    )
    view.add_argument("run", type=Path, help="the run folder (holds rig.ulg)")
    view.add_argument("--port", type=int, default=VIEW_PORT,
                      help=f"port on 127.0.0.1 (default {VIEW_PORT})")  # fmt: skip
    identify = commands.add_parser(
        "identify",
        help="identify hover, roll/pitch plant and inertia from a flight log",
        description="Estimate a vehicle's parameters from a PX4-style ULog, each with its "
        "uncertainty, method and window; --toml prints them as vehicle-file lines.",
    )
    identify.add_argument("log", type=Path, help="PX4-style ULog (real flight, SITL or rig)")
    identify.add_argument("--vehicle", default=None, metavar="NAME|PATH",
                          help="vehicle file (default: from the log's SYS_AUTOSTART)")  # fmt: skip
    identify.add_argument("--window", type=float, nargs=2, metavar=("START", "END"),
                          help="boot seconds of the rate-loop fit (default: airborne)")  # fmt: skip
    identify.add_argument("--toml", action="store_true",
                          help="print [body]/[propulsion] lines for the vehicle file")  # fmt: skip
    identify.add_argument("--vibration", action="store_true",
                          help="fit the IMU noise and the vibration per operating point instead "
                               "and print [imu]/[vibration] lines")  # fmt: skip
    identify.add_argument("--raw-imu", type=Path, default=None, metavar="DIR",
                          help="write the log's raw IMU FIFO and the vehicle's IMU model at rest "
                               "(--rest) at the chip's rate as real_/sim_<gyro|accel>.parquet "
                               "tables for a credibility plan, instead")  # fmt: skip
    identify.add_argument("--rest", type=float, nargs=2, metavar=("START", "END"),
                          help="with --raw-imu: boot seconds the rotors are stopped")  # fmt: skip
    identify.add_argument("--imu-hz", type=float, default=800.0,
                          help="the replay's IMU rate the vibration is fitted at (default 800, "
                               "PX4's lockstep at the X500's IMU_GYRO_RATEMAX)")  # fmt: skip
    schema = commands.add_parser(
        "schema",
        help="write the JSON Schema of each configuration file (for TOML editors)",
        description="Write <kind>.schema.json for the scenario, vehicle, campaign and plan "
        "files; a TOML file starting with '#:schema PATH' is then checked by its editor.",
    )
    schema.add_argument(
        "--out", type=Path, default=Path("schemas"), help="folder (default schemas/)"
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    console = Console(stderr=True)
    if args.command == "schema":
        try:
            written = write_schemas(args.out)
        except OSError as error:
            print(f"rig: error: {args.out}: cannot write the schemas ({error.strerror})",
                  file=sys.stderr)  # fmt: skip
            return 1
        for path in written:
            console.print(str(path), highlight=False)
        return 0
    if args.command == "campaign":
        return _campaign(args, console)
    if args.command == "identify":
        return _identify(args)
    if args.command == "plot":
        return _plot(args, console)
    if args.command == "view":
        return _view(args, console)
    signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        result = _replay(args, console) if args.command == "replay" else _run(args, console)
    except RigError as error:
        print(f"rig: error: {error}", file=sys.stderr)  # one line, never wrapped
        return 1
    except KeyboardInterrupt:
        print("rig: interrupted; the logs written so far are readable", file=sys.stderr)
        return 130
    except Terminated:
        print("rig: terminated (SIGTERM); the logs written so far are readable", file=sys.stderr)
        return 143
    console.print(
        f"done: {result.simulated_s:.1f} s simulated in {result.wall_s:.1f} s "
        f"(RTF {result.real_time_factor:.2f}x, {result.frames} frames)\n"
        f"autopilot:     {result.autopilot}\n"
        f"rig log:       {result.rig_log}\n"
        f"autopilot log: {result.autopilot_log or '(written by the autopilot, e.g. PX4)'}",
        highlight=False,
    )
    try:
        plots = _plot_names(plot_run(result.run_dir))
        console.print(f"plots:         {plots}", highlight=False, soft_wrap=True)
    except RigError as error:  # the run itself succeeded: say so, keep exit 0
        print(f"rig: warning: no plots: {error}", file=sys.stderr)
    return 0


def _plot(args: argparse.Namespace, console: Console) -> int:
    """``rig plot RUN``: remake the plots of a finished run."""
    try:
        console.print(f"plots: {_plot_names(plot_run(args.run))}", highlight=False, soft_wrap=True)
    except RigError as error:
        print(f"rig: error: {error}", file=sys.stderr)
        return 1
    return 0


def _view(args: argparse.Namespace, console: Console) -> int:
    """``rig view RUN``: serve the run's playback until Ctrl-C (the only way it ends: 0)."""
    try:
        server = ViewServer(args.port, recording=load_recording(args.run))
    except RigError as error:
        print(f"rig: error: {error}", file=sys.stderr)
        return 1
    console.print(f"playback of {args.run}: {server.url} (Ctrl-C stops)", highlight=False)
    with server, contextlib.suppress(KeyboardInterrupt):
        threading.Event().wait()
    return 0


def _plot_names(paths: list[Path]) -> str:
    return f"{paths[0].parent}/{{{','.join(p.name for p in paths)}}}"


def _run(args: argparse.Namespace, console: Console) -> RunResult:
    """``rig run`` and ``rig hil-sim``."""
    scenario = load_scenario(HIL_SIM_SCENARIO if args.command == "hil-sim" else args.scenario)
    if args.vehicle is not None:
        scenario = dataclasses.replace(scenario, vehicle=args.vehicle)
    options = dataclasses.replace(
        _run_options(args),
        on_waiting=lambda command: console.print(
            f"waiting for PX4; start it with:\n  {command}", highlight=False, soft_wrap=True
        ),
    )
    _announce(console, scenario.name, scenario.description,
              options.sensor_layer or scenario.sensor_layer, options)  # fmt: skip
    with _live_view(args, console, scenario.name) as view:
        return _run_with_progress(console, lambda p: run_scenario(scenario, options, p), view)


def _replay(args: argparse.Namespace, console: Console) -> RunResult:
    """``rig replay``: the plan first (a bad log fails before anything starts), then the run."""
    given = {"sensor_layer": args.sensor_layer, "imu_hz": args.imu_hz}
    replay_options = ReplayOptions(
        drive=args.drive, window_s=tuple(args.window) if args.window else None,
        start_s=args.start, end_s=args.end, vehicle=args.vehicle, seed=args.seed,
        autopilot=args.autopilot, px4_dir=args.px4,
        **{name: value for name, value in given.items() if value is not None},
    )  # fmt: skip
    plan = plan_replay(args.log, replay_options)
    options = _run_options(args)
    how = "as its pilot flew it" if plan.px4 else f"{plan.drive} drive"
    _announce(console, f"replay of {plan.log_path.name}",
              f"{how}, {plan.start_s:.3f}-{plan.end_s:.3f} s, vehicle "
              f"{plan.vehicle} ({plan.vehicle_reason}), {len(plan.parameters)} parameters "
              f"from the log", replay_options.sensor_layer, options)  # fmt: skip
    for level, text in plan.notes:
        console.print(f"{level}: {text}", highlight=False)
    with _live_view(args, console, f"replay of {plan.log_path.name}") as view:
        return _run_with_progress(console, lambda p: run_replay(plan, options, p), view)


def _run_options(args: argparse.Namespace) -> RunOptions:
    return RunOptions(
        autopilot=args.autopilot,
        instance=args.instance,
        out_dir=args.out,
        sensor_layer=args.sensor_layer,
        duration_s=getattr(args, "duration", None),
        timeouts=LinkTimeouts(connect_s=args.connect_timeout),
        autopilot_params=tuple(args.param),
        px4_dir=args.px4,
        speed=args.speed if args.speed is not None else DEFAULT_SPEED.get(args.command, math.inf),
        force=args.force,
    )


def _announce(console: Console, name: str, description: str, sensor_layer: str,
              options: RunOptions) -> None:  # fmt: skip
    ports = Ports(options.instance)
    console.print(
        f"[bold]{name}[/]: {description}\n"
        f"sensor layer {sensor_layer}, autopilot {options.autopilot}, simulator link TCP "
        f"{ports.simulator_tcp}; a ground station can watch on UDP {ports.gcs_remote_udp} "
        "(QGroundControl, MAVProxy)"
    )


def _add_run_options(parser: argparse.ArgumentParser, *, scenario: bool = True) -> None:
    """Options of every closed-loop run; ``scenario``: also those a replay takes from the log."""
    parser.add_argument("--sensor-layer", choices=list(SensorLayer), default=None,
                        help="default: the scenario's (tlm for a replay)")  # fmt: skip
    parser.add_argument("--instance", type=int, default=0, help="SITL instance i: ports +i")
    parser.add_argument("--out", type=Path, default=None,
                        help="run folder (default runs/<name>-<UTC time>)")  # fmt: skip
    parser.add_argument("--autopilot", choices=AUTOPILOTS, default="reference",
                        help="reference (embedded) or px4 (PX4 SITL)")  # fmt: skip
    parser.add_argument("--px4", type=Path, default=None, metavar="DIR",
                        help="PX4 SITL build (bin/px4 + etc/) the rig starts; default "
                             "$PX4_DIR, else the rig waits for a PX4 you start")  # fmt: skip
    if scenario:
        parser.add_argument("--duration", type=float, default=None,
                            help="simulated seconds (default: the scenario's)")  # fmt: skip
        parser.add_argument("--vehicle", default=None, metavar="NAME|PATH",
                            help="vehicle file instead of the scenario's")  # fmt: skip
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="autopilot parameter, PX4's names (repeatable)")  # fmt: skip
    parser.add_argument("--speed", type=_speed, default=None, metavar="FACTOR|max",
                        help="at most FACTOR × real time, kept by sleeping (default: 1 for "
                             "hil-sim, which you watch; max otherwise)")  # fmt: skip
    parser.add_argument("--force", action="store_true",
                        help="overwrite the logs of a run already in --out")  # fmt: skip
    parser.add_argument("--connect-timeout", type=float, default=60.0,
                        help="seconds to wait for the autopilot to connect")  # fmt: skip
    parser.add_argument("--view", action="store_true",
                        help="watch the flight live in a browser (the URL is printed)")  # fmt: skip
    parser.add_argument("--view-port", type=int, default=None, metavar="PORT",
                        help=f"--view's port on 127.0.0.1 (default {VIEW_PORT} + instance; "
                             "0: any free one)")  # fmt: skip


@contextlib.contextmanager
def _live_view(
    args: argparse.Namespace, console: Console, name: str
) -> Iterator[Callable[[Progress], None] | None]:
    """``--view``: the page's server for one run, or None. A port already taken is a
    one-line warning and the run goes on without a view: the flight matters more."""
    if not args.view:
        yield None
        return
    port = args.view_port if args.view_port is not None else VIEW_PORT + args.instance
    try:
        server = ViewServer(port, name=name)
    except ViewError as error:
        print(f"rig: warning: no live view: {error}", file=sys.stderr)
        yield None
        return
    console.print(f"live view: {server.url}", highlight=False)
    with server:
        yield server.publish


def _campaign(args: argparse.Namespace, console: Console) -> int:
    from rig.apps.campaign import campaign_executor, load_campaign, run_campaign  # on demand
    from rig.apps.campaign_report import write_report

    try:
        if args.campaign == "report":
            if args.folder is None:
                raise RigError("campaign report: give the results folder (rig campaign report DIR)")
            console.print(f"report: {write_report(args.folder)}", highlight=False)
            return 0
        campaign = load_campaign(args.campaign)
        out = args.out or RUNS_DIR / f"campaign-{campaign.name}"
        console.print(f"[bold]{campaign.name}[/]: {campaign.description}\nresults in {out}")
        with campaign_executor(args.scheduler, args.workers) as executor:
            run_campaign(campaign, out, executor, lambda r: console.print(
                f"case {r.index:4d} {r.status:8s} {r.wall_s:6.1f} s  {r.reason}",
                highlight=False, soft_wrap=True,
            ))  # fmt: skip
        console.print(f"report: {write_report(out)}", highlight=False)
    except RigError as error:
        print(f"rig: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("rig: interrupted; finished cases are saved, rerun to resume", file=sys.stderr)
        return 130
    return 0


def _identify(args: argparse.Namespace) -> int:
    """``rig identify``: the table (or ``--toml`` lines) on stdout, errors as one line."""
    from quad_model.vehicle import VehicleFileError, load_vehicle  # on demand
    from rig.apps import identify

    try:
        vehicle = load_vehicle(args.vehicle or identify.vehicle_name_for_log(args.log))
        if args.raw_imu is not None:
            from rig.apps import vibration  # on demand

            if args.rest is None:
                raise identify.IdentificationError("--raw-imu needs --rest START END")
            for path in vibration.write_raw_imu_tables(
                args.log, vehicle, tuple(args.rest), args.raw_imu
            ):
                print(path)
            return 0
        if args.vibration:
            from rig.apps import vibration  # on demand

            measured = vibration.read_log_vibration(args.log)
            fitted, _ = vibration.fit_vibration(vehicle, measured, args.imu_hz)
            print(vibration.vibration_toml(fitted, measured, args.imu_hz), end="")
            return 0
        window = tuple(args.window) if args.window else None
        result = identify.identify_vehicle(args.log, vehicle, window)
    except (RigError, VehicleFileError) as error:
        print(f"rig: error: {error}", file=sys.stderr)
        return 1
    if args.toml:
        print(identify.identification_toml(result, vehicle), end="")
    else:
        Console(width=160).print(identify.identification_table(result))
    return 0


#: Without a terminal (a pipe, a CI log) progress is a plain line this often, in simulated s.
LOG_PROGRESS_EVERY_S = 10.0


def _status(progress: Progress) -> str:
    return (
        f"t = {progress.time_s:6.1f} / {progress.duration_s:.0f} s  "
        f"RTF {progress.real_time_factor:5.2f}x  alt {progress.altitude_m:6.2f} m  "
        f"{'ARMED' if progress.armed else 'disarmed'}  {progress.last_event[:60]}"
    )


def _run_with_progress(
    console: Console,
    run: Callable[[Callable[[Progress], None]], RunResult],
    view: Callable[[Progress], None] | None = None,
) -> RunResult:
    """Run with a live status line (simulated time, RTF, altitude, mode) on a terminal,
    and one plain line every LOG_PROGRESS_EVERY_S of simulated time otherwise; every
    report also goes to ``view`` (the live view's slot) when there is one."""
    if not console.is_terminal:
        next_line_s = 0.0

        def log_line(progress: Progress) -> None:
            nonlocal next_line_s
            if progress.time_s >= next_line_s:
                console.print(_status(progress), highlight=False)
                next_line_s += LOG_PROGRESS_EVERY_S

        return run(_and_view(log_line, view))
    with Live(console=console, refresh_per_second=4, transient=False) as live:
        return run(_and_view(lambda p: live.update(Text(_status(p))), view))


def _and_view(
    show: Callable[[Progress], None], view: Callable[[Progress], None] | None
) -> Callable[[Progress], None]:
    if view is None:
        return show

    def both(progress: Progress) -> None:
        show(progress)
        view(progress)

    return both


if __name__ == "__main__":
    sys.exit(main())
