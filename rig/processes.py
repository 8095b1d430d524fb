"""Child processes the rig starts in their own session (autopilots, campaign cases): how
one is started, stopped and how its end is told, in one place.

Each child starts through this module's launcher (``python -m rig.processes PID ARGV…``),
which sets the child up and then ``exec``\\ s it. A ``preexec_fn`` could do that set-up,
but Python would run it between ``fork`` and ``exec``, in a copy of a process whose other
threads may hold locks mid-call: the rig often runs in a thread beside others (MAVSDK's
gRPC in the tests, the live view's server, Dask), and that can deadlock or crash. Without
one, :mod:`subprocess` starts the child with ``vfork``, which runs nothing of the parent's.
"""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import IO, NoReturn

#: ``prctl`` option: the signal a process gets when its parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1


def start_child(argv: Sequence[str], *, cwd: Path | None = None,
                env: dict[str, str] | None = None, stdin: int | IO[bytes] | None = None,
                stdout: int | IO[bytes] | None = None,
                stderr: int | IO[bytes] | None = None) -> subprocess.Popen[bytes]:  # fmt: skip
    """Start ``argv`` in a session of its own (a Ctrl-C at the rig's terminal reaches the
    rig alone, which stops its children in order), through the launcher, which
    ``exec``\\ s it as the same process. Returns once it has, as :class:`subprocess.Popen`
    does, and raises :class:`OSError` as it does when ``argv`` cannot be run.

    The launcher gives the child what it needs to be stopped cleanly, whatever the rig
    inherited:

    - SIGINT at its default action. A shell ignores SIGINT in what it starts in the
      background (``nohup … &``, CI jobs, cron), and a child inherits that across
      ``exec``: the rig's SIGINT would do nothing, and the child be killed before
      closing its log.
    - Linux: SIGKILL when the rig dies, even by SIGKILL itself (the kernel's parent-death
      signal, sent when the thread that started the child ends: the rig stops its children
      before then). PX4 never exits on its own once its simulator is gone, and a
      reference autopilot would connect to the next rig on its ports. Elsewhere the rig
      still stops its children on every way out it controls.
    """
    # as subprocess does: a pipe closed on exec, which carries the errno if exec fails
    exec_read, exec_write = os.pipe()
    with os.fdopen(exec_read, "rb") as exec_failure:
        try:
            launcher = [sys.executable, "-m", "rig.processes", str(os.getpid()), str(exec_write)]
            process = subprocess.Popen([*launcher, *argv], cwd=cwd, env=env, stdin=stdin,
                                       stdout=stdout, stderr=stderr, start_new_session=True,
                                       pass_fds=(exec_write,))  # fmt: skip
        finally:
            os.close(exec_write)
        try:
            failure = exec_failure.read()
        except BaseException:  # Ctrl-C, SIGTERM: the launcher, stopped or slow, is no child yet
            process.kill()
            process.wait()
            raise
    if failure:
        process.wait()
        code, _, reason = failure.decode().partition(" ")
        raise OSError(int(code), reason, argv[0])
    return process


def _launch(parent: int, exec_write: int, argv: list[str]) -> NoReturn:
    """The launcher's work in the child: SIGINT to its default, the parent-death signal,
    then ``exec`` (the same process, so the rig's :class:`subprocess.Popen` is the child's),
    or the errno and reason on ``exec_write`` for :func:`start_child` to raise."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # the rig died before prctl: nothing would stop this child
        raise SystemExit(1)
    os.set_inheritable(exec_write, False)  # closed by a successful exec
    try:
        os.execvp(argv[0], argv)
    except OSError as error:
        os.write(exec_write, f"{error.errno} {error.strerror}".encode())
        raise SystemExit(127) from None


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


if __name__ == "__main__":
    _launch(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3:])
