"""Plots of a finished run, written into its folder after every ``rig run`` / ``rig replay``
and remade by ``rig plot RUN``: the flight against its setpoints, the motors, and the IMU's
spectra, with faults (red) and commands (grey) marked where they happened.

Reads ``rig.ulg`` (the truth and the sensors as delivered) and the autopilot's own log
(``px4.ulg`` or ``autopilot.ulg``: estimate and setpoints, PX4's topic names either way).
PX4's local frame starts where its EKF aligned with GPS, so its estimate and setpoints may
sit a constant offset from the truth; the legend says which frame a curve is in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import matplotlib
import numpy as np
import pyulog
from numpy.typing import NDArray
from scipy import signal

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt

from px4_logs import LogError, read_ulog
from quad_model.frames import euler_from_quat
from rig.errors import RigError
from rig.lockstep.loop import AUTOPILOT_LOGS

#: The plots, by file name (``<name>.png`` in the run folder).
PLOTS = ("position", "attitude", "motors", "imu_psd")
_AXES = ("x (north)", "y (east)", "z (down)")
_ANGLES = ("roll", "pitch", "yaw")
#: The run's logged messages: time (s), level, text.
Events = list[tuple[float, str, str]]


class PlotError(RigError):
    """A run folder without a readable ``rig.ulg``."""


def plot_run(run_dir: Path) -> list[Path]:
    """Write every plot of ``run_dir``; returns the PNG paths. One-line error when the run
    has no readable ``rig.ulg`` (the autopilot's log is optional)."""
    rig = _read(run_dir / "rig.ulg")
    if _topic(rig, "vehicle_local_position_groundtruth") is None:
        raise PlotError(f"{run_dir / 'rig.ulg'}: no vehicle_local_position_groundtruth "
                        "(not a rig log, or cut before its first frame)")  # fmt: skip
    autopilot = next(
        (_read(run_dir / name) for name in AUTOPILOT_LOGS if (run_dir / name).is_file()), None
    )
    events = [(m.timestamp / 1e6, m.log_level_str(), m.message) for m in rig.logged_messages]
    makers: dict[str, Callable[[plt.Figure, pyulog.ULog, pyulog.ULog | None, Events], None]] = {
        "position": _position, "attitude": _attitude, "motors": _motors, "imu_psd": _imu_psd,
    }  # fmt: skip
    paths = []
    for name in PLOTS:
        figure = plt.figure(figsize=(10.0, 7.5))
        try:
            makers[name](figure, rig, autopilot, events)
            path = run_dir / f"{name}.png"
            figure.savefig(path, dpi=90, bbox_inches="tight")
        finally:
            plt.close(figure)
        paths.append(path)
    return paths


def _read(path: Path) -> pyulog.ULog:
    """The log through the project's one reader of ULogs (damage is a one-line error)."""
    if not path.is_file():
        raise PlotError(f"{path}: no such log (is this a run folder?)")
    try:
        ulog, _ = read_ulog(path)
    except LogError as error:
        raise PlotError(str(error)) from None
    return ulog


def _topic(log: pyulog.ULog | None, name: str) -> tuple[np.ndarray, dict] | None:
    """``(time_s, fields)`` of a topic's first instance, None when the log lacks it."""
    if log is None:
        return None
    for data in log.data_list:
        if data.name == name and data.multi_id == 0:
            return data.data["timestamp"] / 1e6, data.data
    return None


def _mark(ax: plt.Axes, events: Events) -> None:
    """Faults and errors as red lines, commands as grey dotted ones."""
    for time_s, level, text in events:
        if level in ("WARNING", "ERROR", "CRITICAL", "ALERT", "EMERGENCY"):
            ax.axvline(time_s, color="tab:red", lw=0.8, alpha=0.7)
        elif ":" in text and ("accepted" in text or "sent" in text):
            ax.axvline(time_s, color="0.6", lw=0.6, ls=":")


def _legend(ax: plt.Axes) -> None:
    """A legend where something was drawn (a log may lack a topic)."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="upper right")


def _faults_legend(figure: plt.Figure, events: Events) -> None:
    faults = [f"{t:.2f} s: {text}" for t, level, text in events if level != "INFO"]
    if faults:
        figure.text(0.01, 0.005, "\n".join(faults[:6]), fontsize=7, color="tab:red", va="bottom")


def _position(
    figure: plt.Figure, rig: pyulog.ULog, autopilot: pyulog.ULog | None, events: Events
) -> None:
    axes = figure.subplots(3, 1, sharex=True)
    truth = _topic(rig, "vehicle_local_position_groundtruth")
    estimate = _topic(autopilot, "vehicle_local_position")
    setpoint = _topic(autopilot, "vehicle_local_position_setpoint")
    for ax, field in zip(axes, "xyz", strict=True):
        if truth is not None:
            ax.plot(truth[0], truth[1][field], "k", lw=1.2, label="truth (rig)")
        if estimate is not None:
            ax.plot(estimate[0], estimate[1][field], lw=1.0, label="estimate (autopilot frame)")
        if setpoint is not None:
            ax.plot(setpoint[0], setpoint[1][field], "--", lw=1.0, label="setpoint")
    _finish(figure, axes, [f"{label} [m]" for label in _AXES], "position", events)


def _euler_deg(fields: dict, prefix: str) -> np.ndarray:
    """Roll, pitch, yaw rows (deg) of a logged quaternion field, by quad_model's convention."""
    quats = np.column_stack([fields[f"{prefix}[{i}]"] for i in range(4)])
    return np.degrees(np.array([euler_from_quat(q) for q in quats]).T)


def _attitude(
    figure: plt.Figure, rig: pyulog.ULog, autopilot: pyulog.ULog | None, events: Events
) -> None:
    axes = figure.subplots(3, 1, sharex=True)
    curves = (
        ("truth (rig)", _topic(rig, "vehicle_attitude_groundtruth"), "q", "k"),
        ("estimate", _topic(autopilot, "vehicle_attitude"), "q", None),
        ("setpoint", _topic(autopilot, "vehicle_attitude_setpoint"), "q_d", None),
    )
    for label, topic, prefix, color in curves:
        if topic is None:
            continue
        angles = _euler_deg(topic[1], prefix)
        for ax, values in zip(axes, angles, strict=True):
            ax.plot(topic[0], values, color=color, lw=1.0, label=label,
                    ls="--" if label == "setpoint" else "-")  # fmt: skip
    _finish(figure, axes, [f"{angle} [deg]" for angle in _ANGLES], "attitude", events)


def _finish(
    figure: plt.Figure,
    axes: NDArray[np.object_],  # of Axes, as Figure.subplots returns them
    ylabels: list[str],
    title: str,
    events: Events,
) -> None:
    """Labels, grid and event marks of a stack of time plots sharing one time axis."""
    for ax, ylabel in zip(axes, ylabels, strict=True):
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        _mark(ax, events)
    _legend(axes[0])
    axes[0].set_title(title)
    axes[-1].set_xlabel("time [s]")
    _faults_legend(figure, events)


def _motors(
    figure: plt.Figure, rig: pyulog.ULog, autopilot: pyulog.ULog | None, events: Events
) -> None:
    commanded, captured = figure.subplots(2, 1, sharex=True)
    motors = _topic(rig, "actuator_motors")
    if motors is not None:  # every motor of the vehicle: the controls past them are NaN
        for i in range(sum(1 for k in motors[1] if k.startswith("control["))):
            control = motors[1][f"control[{i}]"]
            if np.isfinite(control).any():
                commanded.plot(motors[0], control, lw=0.8, label=f"motor {i}")
    outputs = _topic(rig, "actuator_outputs")
    if outputs is not None:
        for i in range(int(outputs[1]["noutputs"].max())):
            captured.plot(outputs[0], outputs[1][f"output[{i}]"], lw=0.8, label=f"channel {i}")
    commanded.set_ylabel("commanded (0..1)")
    captured.set_ylabel("captured PWM [µs]")
    commanded.set_title("motors: the autopilot's commands and the PWM the capture measured")
    for ax in (commanded, captured):
        ax.grid(alpha=0.3)
        _legend(ax)
        _mark(ax, events)
    captured.set_xlabel("time [s]")
    _faults_legend(figure, events)


def _imu_psd(
    figure: plt.Figure, rig: pyulog.ULog, autopilot: pyulog.ULog | None, events: Events
) -> None:
    """Welch PSDs of the IMU as delivered to the autopilot (rig.ulg sensor_combined)."""
    del autopilot, events  # a spectrum has no time axis to mark
    accel_ax, gyro_ax = figure.subplots(2, 1)
    imu = _topic(rig, "sensor_combined")
    if imu is None or imu[0].size < 64:
        accel_ax.set_title("IMU spectra: too few samples")
        return
    rate_hz = 1.0 / float(np.median(np.diff(imu[0])))
    segment = 2 ** min(12, int(math.log2(imu[0].size // 4)))
    for ax, field, unit in ((accel_ax, "accelerometer_m_s2", "(m/s²)²/Hz"),
                            (gyro_ax, "gyro_rad", "(rad/s)²/Hz")):  # fmt: skip
        for i, axis in enumerate("xyz"):
            freqs, psd = signal.welch(imu[1][f"{field}[{i}]"], fs=rate_hz, nperseg=segment)
            ax.semilogy(freqs, psd, lw=0.8, label=axis)
        ax.set_ylabel(f"{field} PSD [{unit}]")
        ax.grid(alpha=0.3, which="both")
        _legend(ax)
    accel_ax.set_title(f"IMU spectra as the autopilot received them ({rate_hz:.0f} Hz, whole run)")
    gyro_ax.set_xlabel("frequency [Hz]")
