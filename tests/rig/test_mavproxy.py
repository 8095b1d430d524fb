"""MAVProxy, typed at as a user types, flies the reference autopilot through the rig.

``mavproxy.py`` runs as a subprocess with its default modules (parameters, MAVLink FTP,
fence, arm, mode, ...) and its commands fed on stdin; its console output is what the test
reads. It connects to the autopilot's ground-station link (UDP 18570+i, ``udpout``) rather
than waiting on 14550: every autopilot on this machine streams to 14550 until a ground
station talks to it, so 14550 would mix other runs' vehicles into this one's console.

The rig runs at real time, so the typed take-off happens before PX4's pre-flight
auto-disarm (COM_DISARM_PRFLT) would act. Mode changes are typed as ``long DO_SET_MODE``:
MAVProxy 1.8.75's ``mode NAME`` hands pymavlink's ``set_mode_px4`` a tuple from its PX4
mode table and fails ("required argument is not a float") with any vehicle whose HEARTBEAT
says PX4.
"""

from __future__ import annotations

import contextlib
import queue
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import pyulog

from rig.autopilots.reference.params import Parameters
from rig.mavlink.px4_api import Ports
from tests.rig.background_rig import RigInBackground, wait_until_bound

pytestmark = pytest.mark.closed_loop
#: The venv's script beside this interpreter (`make test` does not put .venv/bin on PATH).
_BESIDE_PYTHON = Path(sys.executable).with_name("mavproxy.py")
MAVPROXY = str(_BESIDE_PYTHON) if _BESIDE_PYTHON.exists() else shutil.which("mavproxy.py")
#: PX4's DO_SET_MODE arguments: custom-mode flag, main mode AUTO, sub-mode TAKEOFF / LAND.
TAKEOFF_MODE, LAND_MODE = "1 4 2", "1 4 6"
#: Wall seconds for any one expected line (MAVProxy starts in ~3 s on a busy machine).
WAIT_S = 30.0


class Mavproxy:
    """``mavproxy.py`` with a pipe for stdin and its merged output read line by line."""

    def __init__(self, master: str, target_system: int, state_dir) -> None:
        self.process = subprocess.Popen(
            [MAVPROXY, f"--master={master}", f"--target-system={target_system}",
             f"--state-basedir={state_dir}"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        self.output: list[str] = []
        self._lines: queue.Queue[str] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self._lines.put(line.rstrip("\n"))

    def type(self, command: str) -> None:
        self.process.stdin.write(command + "\n")
        self.process.stdin.flush()

    def expect(self, pattern: str, timeout_s: float = WAIT_S) -> re.Match:
        """The first line from now on that matches ``pattern``; fails with the console."""
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self._lines.get(timeout=left)
            except queue.Empty:
                break
            self.output.append(line)
            if match := re.search(pattern, line):
                return match
        tail = "\n".join(self.output[-30:])
        raise AssertionError(f"MAVProxy printed no {pattern!r} within {timeout_s} s:\n{tail}")

    def command(self, command: str, ack_name: str, timeout_s: float = WAIT_S) -> None:
        """Type ``command`` until its COMMAND_ACK says ACCEPTED (the autopilot refuses a mode
        it cannot fly yet, before its position estimate exists)."""
        deadline = time.monotonic() + timeout_s
        while True:
            self.type(command)
            ack = self.expect(rf"Got COMMAND_ACK: {ack_name}: (\w+)", 5.0).group(1)
            if ack == "ACCEPTED":
                return
            assert time.monotonic() < deadline, f"{command!r} still {ack} after {timeout_s} s"
            time.sleep(1.0)

    def close(self) -> str:
        """Exit MAVProxy; returns everything it printed."""
        with contextlib.suppress(BrokenPipeError):  # it may have gone already
            self.type("exit")
            self.process.stdin.close()
        try:
            self.process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self._reader.join(timeout=5)
        self.process.stdout.close()
        while not self._lines.empty():
            self.output.append(self._lines.get())
        return "\n".join(self.output)


@pytest.mark.skipif(MAVPROXY is None, reason="MAVProxy is not installed (pip install -e .[dev])")
def test_mavproxy_connects_downloads_parameters_and_flies(tmp_path, free_instance):
    """Connect, parameter download without MAVLink-FTP time-outs, mode changes, arm,
    take-off, land and the disarm after landing, all as MAVProxy prints them, and no
    spurious "fence breach"."""
    instance = free_instance()
    ports = Ports(instance)
    rig = RigInBackground(tmp_path, instance, duration_s=45.0, speed=1.0)
    wait_until_bound(ports.gcs_local_udp, 60.0)
    mavproxy = Mavproxy(f"udpout:127.0.0.1:{ports.gcs_local_udp}", ports.system_id,
                        tmp_path / "mavproxy")  # fmt: skip
    try:
        mavproxy.expect(rf"Detected vehicle {ports.system_id}:1")
        connected = time.monotonic()
        count = int(mavproxy.expect(r"Received (\d+) parameters").group(1))
        parameters_s = time.monotonic() - connected
        mavproxy.command(f"long DO_SET_MODE {TAKEOFF_MODE}", "DO_SET_MODE")
        mavproxy.expect(r"Mode TAKEOFF")
        mavproxy.command("arm throttle", "COMPONENT_ARM_DISARM")
        mavproxy.expect(r"\bARMED")
        for _ in range(20):  # climbing to MIS_TAKEOFF_ALT, 2.5 m
            mavproxy.type("status GLOBAL_POSITION_INT")
            height_m = int(mavproxy.expect(r"relative_alt : (-?\d+)").group(1)) / 1000
            if height_m > 2.2:
                break
            time.sleep(1.0)
        assert height_m > 2.2
        mavproxy.command(f"long DO_SET_MODE {LAND_MODE}", "DO_SET_MODE")
        mavproxy.expect(r"Mode LAND")
        mavproxy.expect(r"DISARMED")
    finally:
        console = mavproxy.close()
    result = rig.finish(timeout_s=60)
    assert count == len(Parameters())  # all of them, by the parameter protocol
    assert parameters_s < 5.0, parameters_s  # FTP refused at once: no 1 s retries, no time-out
    assert "FTP: request timed out" not in console
    assert "fence breach" not in console
    truth = pyulog.ULog(str(result.rig_log)).get_dataset("vehicle_local_position_groundtruth")
    altitude_m = -truth.data["z"]
    assert 2.2 < np.max(altitude_m) < 2.9
    assert altitude_m[-1] < 0.1
