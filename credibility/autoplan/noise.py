"""η_p: the vehicle's states the IMU's noise is compared in: at rest (disarmed, the props
stopped), armed at idle on the ground, and in steady hover."""

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from credibility.autoplan.draft import Found, PlannedTest, runs, span, without_path
from credibility.plan import NotScorable
from px4_logs import FlightLog, LogError

#: The paper's ε_p ≈ 10 % of p_e for sensor noise (Table 1), from the measuring uncertainty.
SENSOR_NOISE_K_P = 0.10
#: A σ from n samples is uncertain by σ/√(2(n − 1)); below this count that alone exceeds
#: ε_p = SENSOR_NOISE_K_P·σ, and an exact model could fail.
MIN_SIGMA_SAMPLES = math.ceil(1 + 1 / (2 * SENSOR_NOISE_K_P**2))
#: The vibration in hover is counted above the pilot's motion (x500_validation.toml).
HOVER_HIGHPASS_HZ = 5.0
#: After a disarm the props coast down for a few tenths of a second; the rest segment starts
#: after it. The X500's accelerometer σ over 0.1 s falls from 0.18 to 0.03 m/s² within
#: 0.5 s of its disarm and then stays there; the X8's large props coast for 0.46 s.
DISARM_COAST_S = 0.5
#: No segment starts this soon after the log's first sample: a log that starts armed (PX4
#: logs from the arming) is replayed by an autopilot that must start up first (the rig's
#: reference autopilot arms 1 s in), so the sim is not in the log's state there yet.
LOG_START_S = 1.0
#: A state's segment keeps this far from its ends: one sample of the 10 Hz motor outputs, so
#: no transition (spool-up, arming) falls inside.
STATE_MARGIN_S = 0.1
#: Motors at idle: every normalised motor command at most this (PX4's idle is 0 or a few
#: thousandths; a spin-up passes 0.01 within 0.1 s).
IDLE_MOTOR_MAX = 0.01
#: The six σ tests: (name prefix, signal, unit), gyro and accelerometer per axis.
IMU_SIGNALS = tuple(
    (f"{sensor}_{axis}", f"sensor_combined.{field}[{index}]", unit)
    for sensor, field, unit in (("gyro", "gyro_rad", "rad/s"),
                                ("accel", "accelerometer_m_s2", "m/s²"))
    for index, axis in enumerate("xyz")
)  # fmt: skip
#: A state's segment and how it was found; None when the log has no such state.
StateSegment = tuple[tuple[float, float], str] | None


def imu_rate_hz(log: FlightLog) -> float:
    """The real sensor_combined's averaging rate, which every σ is compared at.

    PX4 logs sensor_combined as its means over 1/IMU_INTEG_RATE (vehicle_imu), so that
    parameter is the rate (200 for a log at 201.7 Hz); a log without it gives its median
    rate rounded to 10 Hz.
    """
    if "IMU_INTEG_RATE" in log.parameters:
        return float(log.parameters["IMU_INTEG_RATE"])
    time_s = log.time_s("sensor_combined")
    return float(round(1.0 / float(np.median(np.diff(time_s))), -1))


def _noise_tests(
    log: FlightLog, state: str, segment: tuple[float, float], armed: bool, how: str
) -> Found:
    """The six σ tests of one state over ``segment``, or why its σ would be unreliable."""
    rate = imu_rate_hz(log)
    time_s = log.time_s("sensor_combined")
    samples = int(np.count_nonzero((time_s >= segment[0]) & (time_s <= segment[1])))
    samples = min(samples, int((segment[1] - segment[0]) * rate))  # after the averaging
    if samples < MIN_SIGMA_SAMPLES:
        reason = (f"{how}, but {segment[0]:.2f}-{segment[1]:.2f} s holds {samples} "
                  f"sensor_combined samples at {rate:g} Hz, fewer than the "
                  f"{MIN_SIGMA_SAMPLES} a σ needs to be known within ε_p "
                  f"= {SENSOR_NOISE_K_P:.0%}")  # fmt: skip
        return [], [NotScorable(name=f"imu_sigma_{state}", kind="performance", reason=reason)]
    found = f"{how}: {segment[0]:.2f}-{segment[1]:.2f} s, {samples} samples at {rate:g} Hz."
    tests = []
    for prefix, signal, unit in IMU_SIGNALS:
        keys: dict[str, Any] = {"kind": "performance", "parameter": "std", "signal": signal,
                                "segment_s": segment, "armed": armed}  # fmt: skip
        if state == "hover":
            keys["highpass_hz"] = HOVER_HIGHPASS_HZ
        keys |= {"k_p": SENSOR_NOISE_K_P, "average_hz": rate, "unit": unit}
        tests.append(PlannedTest(f"{prefix}_sigma_{state}", "performance", found, keys))
    return tests, []


def _armed_changes(log: FlightLog) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """When the arming state was logged and whether armed: LogError when the log has none."""
    arming = log.armed_samples()
    if arming is None:
        raise LogError(
            f"{log.path}: no arming state in the log (neither actuator_armed nor "
            "vehicle_status): motors stopped and at idle cannot be told apart"
        )
    return arming


def rest_segment(log: FlightLog) -> StateSegment:
    """The longest stretch with the motors stopped (disarmed), DISARM_COAST_S after a
    disarm while the props coast down: the IMU's own noise floor. None when the log never
    shows the vehicle disarmed."""
    time_s, armed = _armed_changes(log)
    sensor = log.time_s("sensor_combined")
    best: tuple[float, float] | None = None
    how = ""
    for start, end, state in runs(time_s, armed.astype(float), log.last_s):
        if state:
            continue
        after_disarm = start > time_s[0]
        first = start + (DISARM_COAST_S if after_disarm else 0.0)
        first = max(first, float(sensor[0]), log.first_s + LOG_START_S) + STATE_MARGIN_S
        # a margin at the log's end too: a replay's last sample may fall a little earlier
        last = min(end, float(sensor[-1])) - STATE_MARGIN_S
        if last > first and (best is None or last - first > best[1] - best[0]):
            best = span(first, last)
            how = (f"Disarmed (motors stopped) from {start:.2f} s"
                   + (f", skipping {DISARM_COAST_S:g} s while the props coast down"
                      if after_disarm else ", before the first arm"))  # fmt: skip
    return None if best is None else (best, how)


def idle_segment(log: FlightLog) -> StateSegment:
    """Armed on the ground with every motor at idle (≤ IDLE_MOTOR_MAX) before the take-off:
    the vibration of the idling rotors. None when the log has no such stretch."""
    time_s, armed = _armed_changes(log)
    if not armed.any():
        return None
    arm_s = float(time_s[np.argmax(armed)])
    try:
        lift_s = log.airborne_span()[0]
    except LogError:
        lift_s = log.last_s
    time_s = log.time_s("actuator_motors")
    motors = log.topic("actuator_motors", "motor commands")
    columns = [np.asarray(values, float) for field, values in motors.items()
               if field.startswith("control[") and np.any(np.isfinite(values))]  # fmt: skip
    # a stopped motor logs NaN (PX4, and the reference autopilot while disarmed)
    highest = np.max(np.nan_to_num(np.column_stack(columns), nan=0.0), axis=1)
    spinning = time_s[(time_s >= arm_s) & (highest > IDLE_MOTOR_MAX)]
    spin_up_s = float(spinning[0]) if spinning.size else log.last_s
    sensor = log.time_s("sensor_combined")
    start = max(arm_s, float(sensor[0]), log.first_s + LOG_START_S) + STATE_MARGIN_S
    end = min(spin_up_s, lift_s, float(sensor[-1])) - STATE_MARGIN_S
    if end <= start:
        return None
    how = (
        f"Armed at {arm_s:.2f} s, every motor command ≤ {IDLE_MOTOR_MAX:g} (idle) until "
        f"{spin_up_s:.2f} s, on the ground"
    )
    return span(start, end), how


def hover_segment(log: FlightLog) -> StateSegment:
    """The longest steady hover (:meth:`px4_logs.FlightLog.hover_windows`: slow, level,
    thrust near its median), high-passed at HOVER_HIGHPASS_HZ so the pilot's corrections
    are not counted as vibration."""
    windows = log.hover_windows()
    if not windows:
        return None
    start, end = max(windows, key=lambda w: w[1] - w[0])
    how = (
        f"Steady hover (the longest of {len(windows)}: |v| and body rates low, thrust "
        f"near its median), {HOVER_HIGHPASS_HZ:g} Hz high-pass"
    )
    return span(start + STATE_MARGIN_S, end - STATE_MARGIN_S), how


def noise_tests(log: FlightLog) -> Found:
    """σ of the IMU at rest, armed at idle and in hover: the paper's Table 1."""
    if "sensor_combined" not in log.topics:
        reason = "the log has no sensor_combined: no IMU to compare"
        return [], [NotScorable(name="imu_sigma", kind="performance", reason=reason)]
    states: tuple[tuple[str, Callable[[FlightLog], StateSegment], bool], ...] = (
        ("rest", rest_segment, False),
        ("idle", idle_segment, True),
        ("hover", hover_segment, True),
    )
    tests: list[PlannedTest] = []
    skipped: list[NotScorable] = []
    for state, finder, armed in states:
        try:
            found = finder(log)
        except LogError as error:
            skipped.append(NotScorable(name=f"imu_sigma_{state}", kind="performance",
                                       reason=f"{without_path(error)}"))  # fmt: skip
            continue
        if found is None:
            reason = {"rest": "the vehicle is never disarmed in the log",
                      "idle": "no armed stretch on the ground with the motors at idle before "
                              "the take-off",
                      "hover": "no steady hover of at least 3 s"}[state]  # fmt: skip
            skipped.append(NotScorable(name=f"imu_sigma_{state}", kind="performance",
                                       reason=reason))  # fmt: skip
            continue
        segment, how = found
        more, less = _noise_tests(log, state, segment, armed, how)
        tests += more
        skipped += less
    return tests, skipped
