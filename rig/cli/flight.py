"""What every closed-loop command (``rig run``, ``rig hil-sim``, ``rig replay``) shares: the
run options, the announcement, the live view, progress on the terminal and the summary."""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

from rich.console import Console
from rich.live import Live
from rich.text import Text

from rig.autopilots import Autopilot
from rig.errors import RigError
from rig.lockstep.loop import Progress, RunOptions, RunResult
from rig.lockstep.pacing import parse_speed
from rig.mavlink.px4_api import Ports
from rig.mavlink.simulator_link import LinkTimeouts
from rig.plots import plot_run
from rig.scenarios.scenario import SensorLayer
from rig.view import VIEW_PORT, ViewError, ViewServer

#: What a flight with progress returns (a run's result, or a study stage's line).
Flown = TypeVar("Flown")
#: Pacing per command: the demo flight is watched in a ground station, so real time.
DEFAULT_SPEED = {"hil-sim": 1.0}
#: Without a terminal (a pipe, a CI log) progress is a plain line this often, in simulated s.
LOG_PROGRESS_EVERY_S = 10.0


def _speed(text: str) -> float:
    try:
        return parse_speed(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_run_options(parser: argparse.ArgumentParser, *, scenario: bool = True) -> None:
    """Options of every closed-loop run; ``scenario``: also those a replay takes from the log."""
    parser.add_argument("--sensor-layer", choices=list(SensorLayer), default=None,
                        help="default: the scenario's (tlm for a replay)")  # fmt: skip
    parser.add_argument("--instance", type=int, default=0, help="SITL instance i: ports +i")
    parser.add_argument("--out", type=Path, default=None,
                        help="run folder (default runs/<name>-<UTC time>)")  # fmt: skip
    parser.add_argument("--autopilot", type=Autopilot, choices=list(Autopilot),
                        default=Autopilot.REFERENCE,
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


def run_options(args: argparse.Namespace) -> RunOptions:
    """The parsed options as the loop takes them."""
    return RunOptions(
        autopilot=args.autopilot,
        instance=args.instance,
        out_dir=args.out,
        sensor_layer=args.sensor_layer,
        duration_s=getattr(args, "duration", None),
        timeouts=LinkTimeouts(connect_s=args.connect_timeout),
        autopilot_params=tuple(args.param),
        px4_dir=args.px4,
        speed=_asked_speed(args),
        force=args.force,
    )


def _asked_speed(args: argparse.Namespace) -> float:
    """``--speed``, or the command's default (real time for hil-sim, else as fast as it can)."""
    return args.speed if args.speed is not None else DEFAULT_SPEED.get(args.command, math.inf)


#: Below this share of ``--speed`` a run says it could not keep it (pacing sleeps in whole
#: milliseconds, so a run that keeps up ends a little under).
KEPT_SPEED_SHARE = 0.97


def speed_shortfall(result: RunResult, speed: float) -> str | None:
    """One line when a run fell short of ``--speed``, saying where its frames' time went."""
    if math.isinf(speed) or result.real_time_factor >= KEPT_SPEED_SHARE * speed:
        return None
    frame_us = result.simulated_s / max(result.frames, 1) * 1e6
    budget, link = result.budget, result.link
    return (
        f"could not keep --speed {speed:g}: it ran at {result.real_time_factor:.2f}x real time; "
        f"each {frame_us:,.0f} µs frame took {budget.total_us:,.0f} µs here, "
        f"{budget.chips_us:,.0f} of them in the chips and {budget.autopilot_wait_us:,.0f} "
        f"waiting for the autopilot, whose answer came late in {link.late_answers:,} of "
        f"{link.answers:,} frames (make bench has the breakdown)"
    )


def announce(console: Console, name: str, description: str, sensor_layer: str,
             options: RunOptions) -> None:  # fmt: skip
    """What is about to fly, and where a ground station can watch it."""
    ports = Ports(options.instance)
    console.print(
        f"[bold]{name}[/]: {description}\n"
        f"sensor layer {sensor_layer}, autopilot {options.autopilot}, simulator link TCP "
        f"{ports.simulator_tcp}; a ground station can watch on UDP {ports.gcs_remote_udp} "
        "(QGroundControl, MAVProxy)"
    )


def fly(
    args: argparse.Namespace,
    console: Console,
    name: str,
    run: Callable[[Callable[[Progress], None]], RunResult],
) -> int:
    """Fly ``run`` with progress (and the live view with ``--view``), then print the summary
    and make the plots."""
    with _live_view(args, console, name) as view:
        result = run_with_progress(console, run, view)
    shortfall = speed_shortfall(result, _asked_speed(args))
    console.print(
        f"done: {result.simulated_s:.1f} s simulated in {result.wall_s:.1f} s "
        f"(RTF {result.real_time_factor:.2f}x, {result.frames} frames)\n"
        + (f"speed:         {shortfall}\n" if shortfall else "")
        + f"autopilot:     {result.autopilot}{_restarted(result)}\n"
        f"rig log:       {result.rig_log}\n"
        f"autopilot log: {result.autopilot_log or '(written by the autopilot, e.g. PX4)'}",
        highlight=False,
    )
    try:
        plots = plot_names(plot_run(result.run_dir))
        console.print(f"plots:         {plots}", highlight=False, soft_wrap=True)
    except RigError as error:  # the run itself succeeded: say so, keep exit 0
        print(f"rig: warning: no plots: {error}", file=sys.stderr)
    return 0


def _restarted(result: RunResult) -> str:
    """The summary's note of an autopilot started more than once."""
    if result.autopilot_starts == 1:
        return ""
    return (f" (started {result.autopilot_starts} times: it stalled in its start-up before "
            "the scenario began; rig.ulg says how)")  # fmt: skip


def plot_names(paths: list[Path]) -> str:
    """``DIR/{a.png,b.png}``: the plots of one run folder on one line."""
    return f"{paths[0].parent}/{{{','.join(p.name for p in paths)}}}"


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


def _status(progress: Progress) -> str:
    return (
        f"t = {progress.time_s:6.1f} / {progress.duration_s:.0f} s  "
        f"RTF {progress.real_time_factor:5.2f}x  alt {progress.altitude_m:6.2f} m  "
        f"{'ARMED' if progress.armed else 'disarmed'}  {progress.last_event[:60]}"
    )


def run_with_progress(
    console: Console,
    run: Callable[[Callable[[Progress], None]], Flown],
    view: Callable[[Progress], None] | None = None,
) -> Flown:
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
