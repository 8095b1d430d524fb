"""Child processes the rig starts in their own session (autopilots, campaign cases): how
one is stopped and how its end is told, in one place."""

from __future__ import annotations

import os
import signal
import subprocess


def stop_process_group(process: subprocess.Popen[bytes], grace_s: float) -> None:
    """SIGINT to the child's process group first, so it closes its logs; SIGKILL if it is
    still running ``grace_s`` later. Nothing when it has already ended."""
    if process.poll() is not None:
        return
    os.killpg(process.pid, signal.SIGINT)
    try:
        process.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()


def exit_description(process: subprocess.Popen[bytes]) -> str | None:
    """``"exit code 1"`` or ``"killed by SIGKILL"`` once the process has ended, else None."""
    code = process.poll()
    if code is None:
        return None
    return f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
