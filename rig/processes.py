"""Child processes the rig starts in their own session (autopilots, campaign cases): how
one is stopped and how its end is told, in one place."""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys

#: ``prctl`` option: the signal a process gets when its parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1
#: The C library, loaded here in the parent: the forked child (``preexec_fn``) must not
#: look it up, which would start ``ldconfig`` between fork and exec.
_LIBC = ctypes.CDLL(None, use_errno=True) if sys.platform.startswith("linux") else None


def restore_sigint() -> None:
    """``preexec_fn`` of a child the rig stops with SIGINT (autopilots, campaign cases):
    SIGINT back to its default action. A shell ignores SIGINT in what it starts in the
    background (``nohup … &``, CI jobs, cron) and a child inherits that across exec: the
    rig's SIGINT would then do nothing, and the child be killed before closing its log."""
    if _LIBC is not None:  # libc's signal(): no Python-level thread checks between fork and exec
        _LIBC.signal(signal.SIGINT, signal.SIG_DFL)
    else:
        signal.signal(signal.SIGINT, signal.SIG_DFL)


def die_with_parent() -> None:
    """``preexec_fn`` for a child that must not outlive the rig (PX4 never exits on its
    own once its simulator is gone): SIGKILL when the rig dies, even by SIGKILL itself.
    Linux only; elsewhere nothing (the rig still stops its children on every way out
    it controls). SIGINT is restored too (:func:`restore_sigint`): PX4 is stopped with it."""
    restore_sigint()
    if _LIBC is not None:
        _LIBC.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)


def stop_process_group(process: subprocess.Popen[bytes], grace_s: float) -> bool:
    """SIGINT to the child's process group first, so it closes its logs; SIGKILL if it is
    still running ``grace_s`` later. Nothing when it has already ended. True when it had
    to be killed (its logs may then miss what it had not yet written)."""
    if process.poll() is not None:
        return False
    os.killpg(process.pid, signal.SIGINT)
    try:
        process.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
        return True
    return False


def exit_description(process: subprocess.Popen[bytes]) -> str | None:
    """``"exit code 1"`` or ``"killed by SIGKILL"`` once the process has ended, else None."""
    code = process.poll()
    if code is None:
        return None
    return f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
