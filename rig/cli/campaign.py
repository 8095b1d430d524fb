"""``rig campaign FILE`` (resumable) and ``rig campaign report DIR``."""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from rig.campaign import campaign_executor, load_campaign, run_campaign, write_report
from rig.cli.command import Command
from rig.errors import RigError
from rig.lockstep.loop import RUNS_DIR


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("campaign", help="campaign TOML (or bundled name), or 'report'")
    parser.add_argument("folder", nargs="?", type=Path, help="with 'report': the results folder")
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="results folder (default runs/campaign-<name>; reruns resume)",
    )
    parser.add_argument("--workers", type=int, default=None,
                        help="local processes (default: the cores given)")  # fmt: skip
    parser.add_argument("--scheduler", default=None, metavar="tcp://HOST:8786",
                        help="run on this Dask cluster instead of local processes")  # fmt: skip


def _campaign(args: argparse.Namespace, console: Console) -> int:
    if args.campaign == "report":
        if args.folder is None:
            raise RigError("campaign report: give the results folder (rig campaign report DIR)")
        console.print(f"report: {write_report(args.folder)}", highlight=False)
        return 0
    campaign = load_campaign(args.campaign)
    settings = campaign.file
    out = args.out or RUNS_DIR / f"campaign-{settings.name}"
    console.print(f"[bold]{settings.name}[/]: {settings.description}\nresults in {out}")
    with campaign_executor(args.scheduler, args.workers) as executor:
        run_campaign(campaign, out, executor, lambda r: console.print(
            f"case {r.index:4d} {r.status:8s} {r.wall_s:6.1f} s  {r.reason}",
            highlight=False, soft_wrap=True,
        ))  # fmt: skip
    console.print(f"report: {write_report(out)}", highlight=False)
    return 0


COMMAND = Command(
    "campaign",
    "run a campaign file (resumable), or `campaign report DIR`",
    "Fly every case of a campaign (a base scenario swept over axes) as a rig run, locally or "
    "on a Dask cluster; rerun to resume. 'rig campaign report DIR' remakes the report of a "
    "results folder.",
    _add_arguments,
    _campaign,
    interrupted="interrupted; finished cases are saved, rerun to resume",
)
