"""The rig flying a scenario without commands in a thread, while a test drives the autopilot
from outside as a user's ground station or script would (MAVSDK, MAVProxy, pymavlink).

Shared by the ground-station tests (``test_mavsdk.py``, ``test_mavproxy.py``,
``test_qgc_connect.py``, ``test_gcs_garbage.py``). ``speed`` paces simulated time against
the wall clock those clients live on.
"""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path

from rig.lockstep.loop import RunOptions, RunResult, run_scenario
from rig.mavlink.simulator_link import LinkTimeouts
from rig.scenarios.scenario import scenario_from_dict


class RigInBackground:
    """``run_scenario`` in a daemon thread; :meth:`finish` joins it and reports its error."""

    def __init__(self, tmp_path: Path, instance: int, duration_s: float, speed: float,
                 **options: object) -> None:  # fmt: skip
        # PX4 v1.14 limit-cycles in yaw below 500 Hz on this vehicle (docs/guide/px4.md); the
        # reference autopilot flies steady at Gazebo's 250 Hz, which keeps these tests light.
        imu_hz = 1000 if options.get("autopilot") == "px4" else 250
        scenario = scenario_from_dict({"name": "idle", "vehicle": "f450_high_precision",
                                       "duration_s": duration_s, "seed": 5,
                                       "rates": {"imu_hz": imu_hz}})  # fmt: skip
        run_options = RunOptions(instance=instance, out_dir=tmp_path / "run", speed=speed,
                                 timeouts=LinkTimeouts(connect_s=60, answer_s=30),
                                 **options)  # fmt: skip
        self.result: RunResult | None = None
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._fly, args=(scenario, run_options),
                                        daemon=True)  # fmt: skip
        self._thread.start()

    def _fly(self, scenario, options: RunOptions) -> None:
        try:
            self.result = run_scenario(scenario, options)
        except BaseException as error:  # reported by the test, not lost in the thread
            self.error = error

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def finish(self, timeout_s: float) -> RunResult:
        """The run's result, once it ended within ``timeout_s`` wall seconds without error."""
        self._thread.join(timeout_s)
        assert not self._thread.is_alive(), "the rig run did not end"
        assert self.error is None, self.error
        assert self.result is not None
        return self.result


def wait_until_bound(port: int, timeout_s: float) -> None:
    """Until the autopilot holds its UDP ``port`` (the reference one binds after compiling
    its kernels, PX4 once its startup script reaches ``mavlink start``)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                return
        time.sleep(0.2)
    raise AssertionError(f"nothing bound UDP {port} within {timeout_s} s")
