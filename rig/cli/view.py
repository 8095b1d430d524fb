"""``rig view RUN``: play a finished run back in the browser."""

from __future__ import annotations

import argparse
import contextlib
import threading
from pathlib import Path

from rich.console import Console

from rig.cli.command import Command
from rig.view import VIEW_PORT, ViewServer, load_recording


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", type=Path, help="the run folder (holds rig.ulg)")
    parser.add_argument("--port", type=int, default=VIEW_PORT,
                        help=f"port on 127.0.0.1 (default {VIEW_PORT})")  # fmt: skip


def _view(args: argparse.Namespace, console: Console) -> int:
    """Serve the run's playback until Ctrl-C (the only way it ends: 0)."""
    server = ViewServer(args.port, recording=load_recording(args.run))
    console.print(f"playback of {args.run}: {server.url} (Ctrl-C stops)", highlight=False)
    with server, contextlib.suppress(KeyboardInterrupt):
        threading.Event().wait()
    return 0


COMMAND = Command(
    "view",
    "play a finished run back in the browser",
    "Serve a finished run's playback on 127.0.0.1 until Ctrl-C.",
    _add_arguments,
    _view,
)
