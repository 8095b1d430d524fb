"""The launcher every child of the rig starts through (``rig.processes.start_child``)."""

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from rig.processes import exit_description, start_child
from tests.sigint import sigint_in_children

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")


def _sigint_ignored_in(argv_start) -> bool:
    """Whether ``cat /proc/self/status``, started by ``argv_start`` from this process while
    it ignores SIGINT (a background job's lot), ignores SIGINT too."""
    with sigint_in_children(ignored=True):
        child = argv_start(["cat", "/proc/self/status"], stdout=subprocess.PIPE)
    status, _ = child.communicate(timeout=30)
    ignored = next(line for line in status.decode().splitlines() if line.startswith("SigIgn:"))
    return bool(int(ignored.split()[1], 16) & 1 << (signal.SIGINT - 1))


def test_a_child_of_a_rig_started_in_the_background_can_still_be_stopped_with_sigint():
    assert _sigint_ignored_in(subprocess.Popen)  # what a child would inherit
    assert not _sigint_ignored_in(start_child)


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return False
    return state not in ("Z", "X")  # a zombie has ended, whoever reaps it


def test_a_child_dies_with_the_rig_even_when_the_rig_is_killed_outright():
    rig = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\n"
         "from rig.processes import start_child\n"
         "print(start_child(['sleep', '120']).pid, flush=True)\n"
         "time.sleep(120)"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert rig.stdout is not None
    child = int(rig.stdout.readline())
    assert Path(f"/proc/{child}/cmdline").read_bytes().startswith(b"sleep\0")
    rig.kill()
    rig.communicate(timeout=30)
    deadline = time.monotonic() + 10
    while _alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(child)


def test_a_command_that_cannot_start_raises_as_popen_does(tmp_path):
    missing = tmp_path / "px4"
    with pytest.raises(FileNotFoundError) as raised:
        start_child([str(missing), "-d"])
    with pytest.raises(FileNotFoundError) as popen_raised:
        subprocess.Popen([str(missing), "-d"])
    assert str(raised.value) == str(popen_raised.value)
    assert raised.value.filename == str(missing)


def test_the_child_is_the_process_the_rig_holds(tmp_path):
    """The launcher has ``exec``\\ ed when it returns: the pid, the exit code and the
    signals are the child's own."""
    child = start_child(["sh", "-c", "read line; echo $$; exit 3"], stdin=subprocess.PIPE,
                        stdout=subprocess.PIPE, cwd=tmp_path)  # fmt: skip
    assert Path(f"/proc/{child.pid}/cmdline").read_bytes().startswith(b"sh\0")
    out, _ = child.communicate(b"\n", timeout=30)
    assert int(out) == child.pid
    assert exit_description(child) == "exit code 3"


class _Interrupted(Exception):
    pass


def _raise_interrupted(signum, frame):
    raise _Interrupted


def test_an_interrupted_start_leaves_no_launcher_behind(tmp_path):
    """Ctrl-C (here SIGUSR1) while the launcher has not yet ``exec``\\ ed, as when it is
    stopped: the rig holds no child to stop yet, so the launcher must not outlive the call."""
    (tmp_path / "sitecustomize.py").write_text(
        "import os, signal\nos.kill(os.getpid(), signal.SIGSTOP)\n"
    )
    previous = signal.signal(signal.SIGUSR1, _raise_interrupted)
    main = threading.main_thread().ident
    assert main is not None
    timer = threading.Timer(1.0, signal.pthread_kill, (main, signal.SIGUSR1))
    timer.start()
    try:
        with pytest.raises(_Interrupted):  # the launcher stops itself before it can exec
            start_child(["sh", "-c", "sleep 60", str(tmp_path)],
                        env={**os.environ, "PYTHONPATH": str(tmp_path)})  # fmt: skip
    finally:
        timer.join()
        signal.signal(signal.SIGUSR1, previous)
    left = [pid for pid in filter(str.isdigit, os.listdir("/proc"))
            if _alive(int(pid)) and str(tmp_path).encode() in _cmdline(pid)]  # fmt: skip
    assert not left


def _cmdline(pid: str) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""
