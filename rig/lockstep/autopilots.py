"""The autopilot of one run, one object per kind (:class:`rig.autopilots.Autopilot`): the
reference autopilot, a process the rig starts; PX4 SITL, from the user's build or started by
hand. The loop asks each the same things: its parameters, how to connect, how scenario
commands reach it, why it exited, what it was and where its log is."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Protocol

from quad_model.vehicle import Vehicle
from rig.autopilots import Autopilot
from rig.autopilots.px4 import Px4Sitl, airframe_parameters, find_px4, px4_parameters
from rig.autopilots.reference.params import is_parameter
from rig.mavlink.px4_api import Ports
from rig.mavlink.simulator_link import SimulatorLink
from rig.processes import exit_description, start_child, stop_process_group

#: Seconds the reference autopilot gets to close its log after SIGINT.
AUTOPILOT_STOP_GRACE_S = 5.0
#: ``(text, level)`` into the run's log at the current frame.
Event = Callable[[str, str], None]


class AutopilotRun(Protocol):
    """One run's autopilot, as the loop sees it."""

    kind: Autopilot
    #: Each scenario command is acknowledged before the next frame, so it acts at a known
    #: frame (the reference autopilot); else conversations run one at a time (PX4).
    barrier: bool
    log_path: Path

    def connect(self, link: SimulatorLink) -> None:
        """Start the autopilot (or wait for it) and accept its simulator connection."""

    def settle(self) -> bool:
        """Do what waits for the autopilot's start-up to end; True once done (the loop
        asks again every few frames until then)."""

    def set_aside_start(self, start: int) -> Path | None:
        """After a stall in its start-up (the autopilot stopped): keep this start's console
        under a name of its own and say where, so the rig can start it again; None when the
        rig does not (it did not start this autopilot, or a stall there is a defect)."""

    def exit_description(self) -> str | None:
        """Why the autopilot's process ended, None while it runs (or it is not ours)."""

    def close(self) -> None:
        """Stop the autopilot so that its log is closed."""

    def description(self) -> str:
        """What flew, for the run's summary."""


class ReferenceAutopilotRun:
    """The embedded reference autopilot, a process the rig starts with the airframe's
    parameters it shares with PX4 (rotor geometry, hover thrust) and then the user's."""

    kind = Autopilot.REFERENCE
    barrier = True

    def __init__(self, run_dir: Path, ports: Ports, parameters: tuple[str, ...],
                 argv: tuple[str, ...] | None, event: Event) -> None:  # fmt: skip
        self.log_path = run_dir / "autopilot.ulg"
        self._argv = argv or (
            sys.executable, "-m", "rig.autopilots.reference",
            "--instance", str(ports.instance), "--log", str(self.log_path),
            *(arg for param in parameters for arg in ("--param", param)),
        )  # fmt: skip
        self._event = event
        self._process: subprocess.Popen[bytes] | None = None

    def connect(self, link: SimulatorLink) -> None:
        self._process = start_child(self._argv)
        link.accept("the reference autopilot (python -m rig.autopilots.reference)",
                    answers_every_frame=True, poll_answers=True)  # fmt: skip

    def settle(self) -> bool:
        """Nothing waits for its start-up."""
        return True

    def set_aside_start(self, start: int) -> Path | None:
        """None: the rig's own autopilot starts alike each time; a stall is a defect."""
        return None

    def exit_description(self) -> str | None:
        return None if self._process is None else exit_description(self._process)

    def close(self) -> None:
        """SIGINT first, so the autopilot closes its log; then SIGKILL if it hangs, which
        the run's log records: the autopilot's own log then misses its last buffer."""
        if self._process is None:
            return
        if stop_process_group(self._process, AUTOPILOT_STOP_GRACE_S):
            self._event(f"the autopilot did not stop within {AUTOPILOT_STOP_GRACE_S:g} s of "
                        "SIGINT and was killed: its log may miss its last half second",
                        "warn")  # fmt: skip

    def description(self) -> str:
        return "the reference autopilot"


class Px4Run:
    """PX4 SITL: started from the user's build with the rig's parameters, or waited for."""

    kind = Autopilot.PX4
    barrier = False

    def __init__(self, px4: Px4Sitl, ports: Ports, imu_hz: int, event: Event,
                 on_waiting: Callable[[str], None] | None) -> None:  # fmt: skip
        self._px4 = px4
        self._ports = ports
        self._imu_hz = imu_hz
        self._event = event
        self._on_waiting = on_waiting
        self.log_path = px4.ulog_path

    def connect(self, link: SimulatorLink) -> None:
        px4, hz = self._px4, self._imu_hz
        if px4.build is not None:
            px4.start()
            self._event(f"started {px4.build.description}: {px4.command()}", "info")
            link.stall_hint = (f"; PX4 {px4.build.tag} was given IMU_GYRO_RATEMAX = "
                               f"IMU_INTEG_RATE = {hz} through {px4.build.hook.value}, see "
                               f"its console {px4.console_path}")  # fmt: skip
            link.accept(f"PX4 (its console: {px4.console_path})")
            return
        link.stall_hint = (
            f"; a PX4 started by hand answers every frame at IMU {hz} Hz only with "
            f"IMU_GYRO_RATEMAX = IMU_INTEG_RATE = {hz}: start it with the command the rig "
            f"printed (it sets them), or in PX4's shell `param set IMU_GYRO_RATEMAX {hz}`, "
            f"`param set IMU_INTEG_RATE {hz}`, `param save` and restart it; with PX4's "
            "defaults fly rates.imu_hz = 250"
        )
        command = px4.command()
        self._event(f"waiting for PX4 SITL on {link.endpoint}: {command}", "info")
        if self._on_waiting is not None:
            self._on_waiting(command)
        link.accept(f"PX4 SITL instance {self._ports.instance}: {command}")

    def settle(self) -> bool:
        """Once PX4's start-up script has ended (one started by hand: at once), hold PX4 to
        one CPU (:meth:`~rig.autopilots.px4.Px4Sitl.settle`)."""
        px4 = self._px4
        if px4.build is None:
            return True
        if not px4.settle():
            return False
        if px4.cpu is not None:
            self._event(f"PX4's start-up script has ended: PX4 held to CPU {px4.cpu}", "info")
        return True

    def set_aside_start(self, start: int) -> Path | None:
        """``px4.log`` becomes ``px4.start-<start>.log`` (a PX4 started by hand: None)."""
        px4 = self._px4
        if px4.build is None or not px4.console_path.is_file():
            return None
        kept = px4.console_path.with_name(f"px4.start-{start}.log")
        px4.console_path.replace(kept)
        return kept

    def exit_description(self) -> str | None:
        return self._px4.exit_description()

    def close(self) -> None:
        self._px4.stop()

    def description(self) -> str:
        lockstep = f"lockstep IMU_GYRO_RATEMAX = IMU_INTEG_RATE = {self._imu_hz} Hz"
        if self._px4.build is None:
            return f"PX4 started by hand ({lockstep} needed)"
        return f"{self._px4.build.description}, {lockstep}"


def autopilot_run(
    kind: Autopilot,
    *,
    vehicle: Vehicle,
    hover_throttle: float,
    imu_hz: int,
    user_parameters: tuple[str, ...],
    sensor_parameters: Mapping[str, float],
    px4_dir: Path | None,
    run_dir: Path,
    ports: Ports,
    argv: tuple[str, ...] | None,
    event: Event,
    on_waiting: Callable[[str], None] | None,
) -> AutopilotRun:
    """The run's autopilot with its parameters (nothing started yet)."""
    if kind is Autopilot.PX4:
        build = find_px4(px4_dir)
        params, lacking = px4_parameters(vehicle, hover_throttle, imu_hz, user_parameters,
                                         build, sensor_parameters)  # fmt: skip
        if lacking:
            assert build is not None
            event(f"not set in PX4 {build.tag}, which has no such parameter: "
                  f"{', '.join(lacking)}", "warn")  # fmt: skip
        return Px4Run(Px4Sitl(build, run_dir, ports.instance, params), ports, imu_hz, event,
                      on_waiting)  # fmt: skip
    # The airframe's and sensors' parameters PX4 gets that the reference autopilot has too
    # (rotor geometry, hover thrust, the aiding sources), then the user's, which win name
    # by name.
    own = airframe_parameters(vehicle, hover_throttle) | dict(sensor_parameters)
    parameters = (
        *(f"{name}={value!r}" for name, value in own.items() if is_parameter(name)),
        *user_parameters,
    )
    return ReferenceAutopilotRun(run_dir, ports, parameters, argv, event)
