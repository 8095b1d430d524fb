"""What the view's page draws: one *frame* (a JSON-ready dict) per instant.

A live run's frames come from the loop's :class:`~rig.lockstep.loop.Progress`; a finished
run's are sampled from its logs (``rig.ulg``, and the autopilot's log for the armed state
and the flight mode), so the page draws both the same way. Keys of a frame:

``t`` run seconds, ``q`` attitude body→NED (w, x, y, z), ``pos``/``vel`` NED (m, m/s),
``motors`` throttles 0..1, ``accel``/``gyro`` the IMU as the autopilot got it, faults and
all (m/s², rad/s, FRD),
``armed``, ``mode`` (PX4's name, None if unknown), ``faults`` (acting now), ``event``
(latest rig event), ``rtf`` (live only).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyulog

from px4_logs import ARMING_STATE_ARMED, LogError, read_ulog
from quad_model.frames import pwm_to_throttle
from rig.errors import RigError
from rig.lockstep.loop import AUTOPILOT_LOGS, Progress

Frame = dict[str, object]
#: Frames per simulated second of a playback (the live view pushes at most ~25 a wall second).
PLAYBACK_HZ = 20
#: Names QGroundControl shows. PX4 px4_custom_mode.h: HEARTBEAT.custom_mode carries the main
#: mode in bits 16-23 and, for AUTO (4), the sub mode in bits 24-31.
_MAIN_MODES = {1: "Manual", 2: "Altitude", 3: "Position", 5: "Acro", 6: "Offboard",
               7: "Stabilized", 9: "Termination"}  # fmt: skip
_AUTO_MAIN_MODE = 4
_AUTO_MODES = {1: "Ready", 2: "Takeoff", 3: "Hold", 4: "Mission", 5: "Return", 6: "Land",
               8: "Follow Me", 9: "Precision Land"}  # fmt: skip
#: The same names by ``vehicle_status.nav_state``, which the autopilot's log holds.
_NAV_STATES = {0: "Manual", 1: "Altitude", 2: "Position", 3: "Mission", 4: "Hold", 5: "Return",
               10: "Acro", 12: "Descend", 13: "Termination", 14: "Offboard", 15: "Stabilized",
               17: "Takeoff", 18: "Land", 19: "Follow Me", 20: "Precision Land",
               21: "Orbit"}  # fmt: skip
#: How ``rig.scenarios.faults`` logs a fault's start and end.
_FAULT_EVENT = re.compile(r"fault (?P<fault>.+) (?P<change>started|ended)")
_RIG_TOPICS = ("vehicle_attitude_groundtruth", "vehicle_local_position_groundtruth",
               "sensor_combined", "actuator_outputs")  # fmt: skip


class ViewError(RigError):
    """No view: a run folder without a readable ``rig.ulg``, or a port the view cannot bind."""


def mode_name(custom_mode: int | None) -> str | None:
    """PX4's name of a HEARTBEAT ``custom_mode`` (None before the first HEARTBEAT)."""
    if custom_mode is None:
        return None
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    name = _AUTO_MODES.get(sub) if main == _AUTO_MAIN_MODE else _MAIN_MODES.get(main)
    return name or f"custom mode {custom_mode:#x}"


def live_frame(progress: Progress) -> Frame:
    """The frame of the loop's latest report (rounded: the page shows mm and 0.1 %)."""
    rtf = progress.real_time_factor
    return {
        "t": round(progress.time_s, 3),
        "q": _rounded(progress.attitude_quat, 5),
        "pos": _rounded(progress.position_ned_m, 4),
        "vel": _rounded(progress.velocity_ned_mps, 3),
        "motors": _rounded(progress.motor_throttles, 4),
        "accel": _rounded(progress.accel_mps2, 3),
        "gyro": _rounded(progress.gyro_radps, 4),
        "armed": progress.armed,
        "mode": mode_name(progress.custom_mode),
        "faults": list(progress.active_faults),
        "event": progress.last_event,
        "rtf": round(rtf, 2) if math.isfinite(rtf) else None,  # JSON has no Infinity
    }


@dataclass(frozen=True)
class Recording:
    """A finished run, ready to play: its frames and every event the rig logged."""

    name: str
    duration_s: float
    frames: list[Frame]
    #: ``{"t", "level", "text"}`` in time order.
    events: list[dict[str, object]]


def load_recording(run_dir: Path) -> Recording:
    """Sample a run folder's logs at :data:`PLAYBACK_HZ`; one-line :class:`ViewError` when
    there is no readable ``rig.ulg`` (the autopilot's log is optional: without it the
    armed state and the mode are unknown)."""
    rig = _read(run_dir / "rig.ulg", _RIG_TOPICS)
    attitude = _topic(rig, "vehicle_attitude_groundtruth")
    position = _topic(rig, "vehicle_local_position_groundtruth")
    step_us = round(1e6 / PLAYBACK_HZ)
    truth_us = [] if position is None else position["timestamp"].tolist()
    if (
        attitude is None
        or position is None
        or len(truth_us) < 2
        or truth_us[-1] - truth_us[0] < step_us
    ):
        raise ViewError(f"{run_dir / 'rig.ulg'}: no ground truth to play "
                        "(not a rig log, or cut before its first frames)")  # fmt: skip
    # The first truth sample is one truth period after the run's start (the loop logs it
    # every N frames from frame N), and the page counts run seconds as the live view does.
    start_us = truth_us[0] - (truth_us[1] - truth_us[0])
    times_us = range(start_us + step_us, truth_us[-1] + 1, step_us)
    imu = _topic(rig, "sensor_combined")
    outputs = _topic(rig, "actuator_outputs")
    status = _autopilot_status(run_dir)
    events = [(round((m.timestamp - start_us) / 1e6, 3), m.log_level_str(), m.message)
              for m in sorted(rig.logged_messages, key=lambda m: m.timestamp)]  # fmt: skip
    frames = []
    for time_us in times_us:
        i = _at(position["timestamp"], time_us)
        q = np.array([attitude[f"q[{k}]"][i] for k in range(4)])  # logged with the position
        t = (time_us - start_us) / 1e6
        frame: Frame = {
            "t": round(t, 3),
            "q": _rounded(q, 5),
            "pos": _rounded((position[a][i] for a in "xyz"), 4),
            "vel": _rounded((position[a][i] for a in ("vx", "vy", "vz")), 3),
            "motors": _motors(outputs, time_us),
            "accel": _rounded(_sample(imu, "accelerometer_m_s2", 3, time_us), 3),
            "gyro": _rounded(_sample(imu, "gyro_rad", 3, time_us), 4),
            "armed": None,
            "mode": None,
            "faults": _faults_at(events, t),
            "event": next((text for at, _, text in reversed(events) if at <= t), ""),
        }
        if status is not None:
            j = _at(status["timestamp"], time_us)
            if j >= 0:
                frame["armed"] = bool(status["arming_state"][j] == ARMING_STATE_ARMED)
                nav_state = int(status["nav_state"][j])
                frame["mode"] = _NAV_STATES.get(nav_state, f"nav_state {nav_state}")
        frames.append(frame)
    return Recording(
        name=run_dir.resolve().name,
        duration_s=round((times_us[-1] - start_us) / 1e6, 3),
        frames=frames,
        events=[{"t": at, "level": level, "text": text} for at, level, text in events],
    )


def _read(path: Path, topics: Iterable[str]) -> pyulog.ULog:
    if not path.is_file():
        raise ViewError(f"{path}: no such log (is this a run folder?)")
    try:
        ulog, _ = read_ulog(path, list(topics))
    except LogError as error:
        raise ViewError(str(error)) from None
    return ulog


def _topic(log: pyulog.ULog, name: str) -> dict[str, np.ndarray] | None:
    return next((d.data for d in log.data_list if d.name == name and d.multi_id == 0), None)


def _at(timestamps: np.ndarray, time_us: int) -> int:
    """Index of the latest sample at or before ``time_us`` (-1: none yet)."""
    return int(np.searchsorted(timestamps, time_us, side="right")) - 1


def _sample(data: dict[str, np.ndarray] | None, field: str, count: int,
            time_us: int) -> list[float]:  # fmt: skip
    if data is None or (i := _at(data["timestamp"], time_us)) < 0:
        return [0.0] * count
    return [float(data[f"{field}[{k}]"][i]) for k in range(count)]


def _motors(outputs: dict[str, np.ndarray] | None, time_us: int) -> list[float]:
    """Throttles from the captured PWM widths, as the loop computes them."""
    widths = _sample(outputs, "output", 4, time_us)
    return _rounded(pwm_to_throttle(widths), 4)


def _autopilot_status(run_dir: Path) -> dict[str, np.ndarray] | None:
    """The autopilot's ``vehicle_status`` (None without its log, or when it lacks one)."""
    for name in AUTOPILOT_LOGS:
        if (run_dir / name).is_file():
            try:
                return _topic(_read(run_dir / name, ("vehicle_status",)), "vehicle_status")
            except ViewError:
                return None  # a damaged autopilot log: play the rig's side anyway
    return None


def _faults_at(events: list[tuple[float, str, str]], t: float) -> list[str]:
    """Faults started and not ended by ``t``, as the rig logged them."""
    active: list[str] = []
    for at, _, text in events:
        if at > t:
            break
        if (match := _FAULT_EVENT.fullmatch(text)) is not None:
            fault = match["fault"]
            if match["change"] == "started":
                active.append(fault)
            elif fault in active:
                active.remove(fault)
    return active


def _rounded(values: Iterable[float], digits: int) -> list[float]:
    return [round(float(v), digits) for v in values]
