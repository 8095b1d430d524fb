"""An automatic test plan: the segments the paper's tests need, found in a real PX4 log.

Writing a plan by hand means reading the flight's timeline for the spans each kind of test
needs: the vehicle at rest, armed at idle and in steady hover for the sensor noise (η_p),
set-point steps for the step responses (η_t), the pilot's inputs for the frequency
responses (η_f). Each finder below looks for one of them with a stated criterion and says
what it found in numbers; what a log cannot give (no GNSS, a slow logging rate, never
airborne) becomes a ``[[not_scorable]]`` entry with the reason. :func:`draft_plan` gathers
them, :func:`plan_toml` writes the plan a user can read, edit and score.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from credibility import indices, spectral
from credibility.assess import ARMING_STATE_ARMED
from credibility.errors import CredibilityError
from credibility.logs import euler_zyx, heading_frame
from credibility.plan import NotScorable
from px4_logs import FlightLog, LogError

# --- the settings every automatic plan shares, as x500_validation.toml chose them -----------

#: The paper's weights (section 4.2.4): frequency counts most for a dynamic system.
PAPER_WEIGHTS = {"performance": 0.3, "time": 0.3, "frequency": 0.4}
#: ε_min = the pass mark: a first identification from one flight rarely reaches the paper's
#: 0.9, and η_all is then still reported as a valid summary when no test falls below 0.6.
EPS_MIN = indices.DEFAULT_PASS_MARK
#: A PX4 log's fast topics come every 20 ms at the default logging profile; a longer gap
#: inside a segment is a dropout.
MAX_GAP_S = 0.2
#: The paper's ε_p ≈ 10 % of p_e for sensor noise (Table 1), from the measuring uncertainty.
SENSOR_NOISE_K_P = 0.10
#: A σ from n samples is uncertain by σ/√(2(n − 1)); below this count that alone exceeds
#: ε_p = SENSOR_NOISE_K_P·σ, and an exact model could fail.
MIN_SIGMA_SAMPLES = math.ceil(1 + 1 / (2 * SENSOR_NOISE_K_P**2))
#: The vibration in hover is counted above the pilot's motion (x500_validation.toml).
HOVER_HIGHPASS_HZ = 5.0
#: Where the user's simulation log goes when ``--sim`` is not given: a name that cannot be
#: mistaken for a real file, so ``credibility report`` says it is missing.
SIM_PLACEHOLDER = "REPLACE-WITH-YOUR-SIMULATION.ulg"

# --- the vehicle's state ------------------------------------------------------------------

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
#: PX4's nav_state values (msg/VehicleStatus.msg) a pilot flies by stick: Manual, Altitude,
#: Position, Position slow, Acro, Stabilized.
PILOT_MODES = frozenset({0, 1, 2, 6, 10, 15})
#: Of those, the modes whose horizontal sticks command a velocity in the heading frame.
HEADING_FRAME_MODES = frozenset({2, 6})

# --- set-point steps (η_t) ----------------------------------------------------------------


@dataclass(frozen=True)
class StepShape:
    """What counts as a step in one kind of set-point, and how its segment is bounded."""

    #: A level: the set-point within this band …
    hold_band: float
    #: … for at least this long.
    hold_s: float
    #: A step moves it from one level to the next by at least this …
    min_change: float
    #: … within this long (a slower change is a drift, not a step).
    max_rise_s: float
    #: The segment starts this long before the step and ends this long after it settled.
    lead_s: float
    settle_s: float
    #: Steps closer than this on one axis are one manoeuvre (a doublet's reversal).
    group_gap_s: float


#: Velocity: 1 m/s within 4 s, as a mission start (0 → 4.8 m/s in 2 s), a take-off (0 →
#: 1.5 m/s up in 1.5 s) or a pilot's stick (0 → 3.4 m/s in 3.3 s) commands it, between
#: levels held within 0.4 m/s (more than a stick's jitter) for 1 s (a ramp of 0.4 m/s² or
#: more holds no level that long); a multicopter's velocity settles within 4 s.
VELOCITY_STEP = StepShape(hold_band=0.4, hold_s=1.0, min_change=1.0, max_rise_s=4.0, lead_s=0.5,
                          settle_s=4.0, group_gap_s=1.0)  # fmt: skip
#: Attitude: between levels held within 3° for 0.2 s (four samples at 20 Hz), 10° within
#: 1 s, well above the ±6° of a hover's corrections; the attitude settles within half a
#: second, and a doublet's reversal follows within 1.5 s.
ATTITUDE_STEP = StepShape(hold_band=3.0, hold_s=0.2, min_change=10.0, max_rise_s=1.0, lead_s=0.1,
                          settle_s=0.5, group_gap_s=1.5)  # fmt: skip
#: Position: a jump of the set-point by 1 m within half a second between levels held within
#: 0.2 m for 1 s (a goto an autopilot hands its position loop unsmoothed, as the paper's
#: level-flight step and the rig's level_step scenario command it; PX4 smooths its own
#: set-points into ramps, which the velocity steps find); a position settles within 8 s.
POSITION_STEP = StepShape(hold_band=0.2, hold_s=1.0, min_change=1.0, max_rise_s=0.5, lead_s=0.5,
                          settle_s=8.0, group_gap_s=1.0)  # fmt: skip
#: A horizontal step starts from a hover: the set-point below this before it (m/s).
HOVER_SPEED_MPS = 0.5
#: A step whose change takes at most this many samples is a step, else a ramp-step.
STEP_SAMPLES = 2

# --- frequency responses (η_f) --------------------------------------------------------------

#: The lift-off, the touch-down and the climb and descent next to them are not the
#: pilot's excitation of the airborne dynamics (ground contact, the land detector's
#: thrust ramps): the spans keep this far from both.
GROUND_S = 5.0
#: Pilot-flown airborne spans shorter than this give too few averages at low frequency.
MIN_EXCITATION_S = 20.0
#: The frequency grid the coherence is searched on, up to this fraction of Nyquist (the
#: estimate's last bins are aliased) …
BAND_TOP_NYQUIST = 0.8
COHERENCE_GRID_POINTS = 60
#: … the coherent band must span at least this ratio f_b/f_a (an octave) …
MIN_BAND_RATIO = 2.0
#: … with at least this share of its grid points coherent.
COHERENT_SHARE = 2.0 / 3.0
#: The points scored across the band (x500_validation.toml).
N_POINTS = 30
#: The responses: (name, input topic and field, output field, caveat).
TORQUE_CAVEAT = (
    "CAVEAT: closed-loop data; at high frequency part of the coherence comes from the "
    "feedback path (the rate D-term acting on measured noise), so the real curve is a "
    "biased plant estimate. The sim has the same loop and the same bias, so sim and real "
    "compare, but neither curve is the open-loop plant."
)
RESPONSES = tuple(
    (f"{axis}_{what}", f"{topic}.{field}", f"vehicle_angular_velocity.xyz[{index}]", caveat)
    for index, axis in enumerate(("roll", "pitch", "yaw"))
    for what, topic, field, caveat in (
        ("rate_response", "vehicle_rates_setpoint", axis, ""),
        ("torque_to_rate", "vehicle_torque_setpoint", f"xyz[{index}]", TORQUE_CAVEAT),
    )
)

#: The responses' topics; the slowest one's rate is every response's sample rate.
RATE_TOPICS = ("vehicle_rates_setpoint", "vehicle_torque_setpoint", "vehicle_angular_velocity")

IMU_SIGNALS = tuple(
    (f"{sensor}_{axis}", f"sensor_combined.{field}[{index}]", unit)
    for sensor, field, unit in (("gyro", "gyro_rad", "rad/s"),
                                ("accel", "accelerometer_m_s2", "m/s²"))
    for index, axis in enumerate("xyz")
)  # fmt: skip


@dataclass(frozen=True)
class PlannedTest:
    """One test of the plan: its keys as the plan file writes them, and what was found."""

    name: str
    kind: indices.Kind
    #: The comment above the test: what the finder found, in numbers, and by what criterion.
    found: str
    keys: dict[str, Any]


@dataclass(frozen=True)
class Draft:
    """A plan found in a log, before it is written."""

    name: str
    description: str
    tests: tuple[PlannedTest, ...]
    not_scorable: tuple[NotScorable, ...]

    @property
    def weights(self) -> dict[str, float]:
        """The paper's weights over the kinds the plan holds, scaled to sum 1."""
        kinds = {test.kind for test in self.tests}
        present = {kind: alpha for kind, alpha in PAPER_WEIGHTS.items() if kind in kinds}
        total = sum(present.values())
        return {kind: round(alpha / total, 6) for kind, alpha in present.items()}


@dataclass(frozen=True)
class Step:
    """A set-point change: from ``start_s`` to ``end_s``, by ``change``, in ``samples``."""

    start_s: float
    end_s: float
    before: float
    after: float
    samples: int

    @property
    def change(self) -> float:
        return self.after - self.before


#: A finder gives its tests, or the entries it could not plan.
Found = tuple[list[PlannedTest], list[NotScorable]]
#: A state's segment and how it was found; None when the log has no such state.
StateSegment = tuple[tuple[float, float], str] | None


# --- the vehicle's states: rest, idle, hover (η_p) ------------------------------------------


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


def runs(
    time_s: NDArray[np.float64], values: NDArray[Any], end_s: float
) -> list[tuple[float, float, float]]:
    """(start, end, value) of each run of equal values of a logged state; the last run ends
    at ``end_s``."""
    changes = np.flatnonzero(np.diff(values)) + 1
    starts = np.concatenate(([0], changes))
    ends = np.append(time_s[changes], max(end_s, float(time_s[-1])))
    return [
        (float(time_s[i]), float(e), float(values[i])) for i, e in zip(starts, ends, strict=True)
    ]


def _armed_changes(log: FlightLog) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """When the arming state was logged and whether armed (``actuator_armed``, else
    ``vehicle_status``): LogError when the log has neither."""
    if "actuator_armed" in log.topics:
        time_s, armed = log.series("actuator_armed", "armed", "arming state")
        return time_s, armed > 0.5
    if "vehicle_status" in log.topics:
        time_s, state = log.series("vehicle_status", "arming_state", "arming state")
        return time_s, state == ARMING_STATE_ARMED
    raise LogError(
        f"{log.path}: no arming state in the log (neither actuator_armed nor vehicle_status): "
        "motors stopped and at idle cannot be told apart"
    )


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
            best = _span(first, last)
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
    return _span(start, end), how


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
    return _span(start + STATE_MARGIN_S, end - STATE_MARGIN_S), how


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
                                       reason=f"{_without_path(error)}"))  # fmt: skip
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


# --- set-point steps (η_t) ------------------------------------------------------------------


def holds(
    time_s: NDArray[np.float64], values: NDArray[np.float64], shape: StepShape
) -> list[tuple[int, int]]:
    """(first, last) sample of each stretch where the set-point stays within
    ``shape.hold_band`` for at least ``shape.hold_s``: the levels a step moves between."""
    found = []
    start = 0
    while start < values.size:
        low = high = values[start]
        end = start
        while end + 1 < values.size:
            low, high = min(low, values[end + 1]), max(high, values[end + 1])
            if high - low > shape.hold_band:
                break
            end += 1
        if time_s[end] - time_s[start] >= shape.hold_s:
            found.append((start, end))
            start = end + 1
        else:
            start += 1
    return found


def steps(time_s: NDArray[np.float64], values: NDArray[Any], shape: StepShape) -> list[Step]:
    """Moves of the set-point from one held level to the next (:func:`holds`) by at least
    ``shape.min_change`` within ``shape.max_rise_s``; non-finite samples are skipped."""
    finite = np.isfinite(values)
    time_s, values = time_s[finite], np.asarray(values, float)[finite]
    found = []
    # the first sample is a level too: a set-point that moves at once (a take-off's) has one
    levels = holds(time_s, values, shape)
    if not levels or levels[0][0] > 0:
        levels.insert(0, (0, 0))
    for (_, before), (after, _) in itertools.pairwise(levels):
        step = Step(float(time_s[before]), float(time_s[after]), float(values[before]),
                    float(values[after]), after - before)  # fmt: skip
        if abs(step.change) >= shape.min_change and step.end_s - step.start_s <= shape.max_rise_s:
            found.append(step)
    return found


def _grouped(found: Sequence[Step], gap_s: float) -> list[list[Step]]:
    """Steps closer than ``gap_s`` as one manoeuvre."""
    groups: list[list[Step]] = []
    for step in found:
        if groups and step.start_s - groups[-1][-1].end_s <= gap_s:
            groups[-1].append(step)
        else:
            groups.append([step])
    return groups


def _span(start: float, end: float) -> tuple[float, float]:
    """[start, end] to the hundredth, inside the times given (a plan file is read by
    people; a segment rounded past the log's end would not be scored)."""
    return math.ceil(start * 100) / 100, math.floor(end * 100) / 100


def _segment(
    group: Sequence[Step], shape: StepShape, inside: tuple[float, float]
) -> tuple[float, float]:
    start = max(group[0].start_s - shape.lead_s, inside[0])
    end = min(group[-1].end_s + shape.settle_s, inside[1])
    return _span(start, end)


def _describe(group: Sequence[Step], unit: str) -> str:
    return ", then ".join(
        f"{s.before:+.3g} → {s.after:+.3g} {unit} in {s.end_s - s.start_s:.2f} s at "
        f"{s.start_s:.2f} s"
        for s in group
    )


def _time_test(signal: str | dict[str, str], segment: tuple[float, float], unit: str,
               max_lag_s: float) -> dict[str, Any]:  # fmt: skip
    return {"kind": "time", "signal": signal, "segment_s": segment, "unit": unit,
            "align": {"method": "none", "max_lag_s": max_lag_s}}  # fmt: skip


def attitude_steps(log: FlightLog, airborne: tuple[float, float]) -> list[PlannedTest]:
    """Roll and pitch set-point steps, ramp-steps and doublets the pilot flew
    (``vehicle_attitude_setpoint`` in a pilot-flown mode: a mission's attitude follows its
    velocity set-point, which the level-flight tests score): ATTITUDE_STEP's change within
    ≤ STEP_SAMPLES samples is a step, a slower one a ramp-step, a reversal within the group
    gap a doublet."""
    series = [log.series("vehicle_attitude_setpoint", f"q_d[{i}]", "attitude set-point steps")
              for i in range(4)]  # fmt: skip
    time_s = series[0][0]
    roll, pitch, _ = euler_zyx(*(values for _, values in series))
    tests = []
    for axis, angle in (("roll", roll), ("pitch", pitch)):
        inside = (time_s >= airborne[0]) & (time_s <= airborne[1])
        found = [step for step in steps(time_s[inside], np.degrees(angle[inside]), ATTITUDE_STEP)
                 if _nav_state_at(log, step.start_s) in PILOT_MODES]  # fmt: skip
        for group in _grouped(found, ATTITUDE_STEP.group_gap_s):
            reverses = any(a.change * b.change < 0 for a, b in itertools.pairwise(group))
            shape = ("doublet" if reverses else
                     "step" if group[0].samples <= STEP_SAMPLES else "ramp_step")  # fmt: skip
            segment = _segment(group, ATTITUDE_STEP, airborne)
            name = f"{axis}_{shape}_{group[0].start_s:.0f}s"
            found_text = (f"{axis.capitalize()} set-point {_describe(group, '°')} "
                          f"({shape.replace('_', '-')}: ≥ {ATTITUDE_STEP.min_change:g}° within "
                          f"{ATTITUDE_STEP.max_rise_s:g} s).")  # fmt: skip
            signal = {"path": f"vehicle_attitude.q.{axis}", "convert": "rad->deg"}
            tests.append(PlannedTest(name, "time", found_text,
                                     _time_test(signal, segment, "deg", 0.3)))  # fmt: skip
    return tests


def _nav_state_at(log: FlightLog, time_s: float) -> int | None:
    value = log.logged_at("vehicle_status", "nav_state", time_s)
    return None if value is None else int(value)


def velocity_steps(log: FlightLog, airborne: tuple[float, float]) -> Found:
    """The take-off climb, the landing descent and hover → level flight, from the velocity
    set-point (``vehicle_local_position_setpoint``): VELOCITY_STEP's change.

    The climb is the first upward step after lift-off, the descent the last downward one
    before touch-down; a horizontal step counts from a hover (set-point below
    HOVER_SPEED_MPS) and is scored along the axis it was commanded in: north/east in the
    autopilot's modes (a mission's path), forward/right of the heading in Position mode
    (the sticks' axes, so a replay whose heading differs still compares the response).
    """
    why = "velocity set-point steps"
    data = log.topic("vehicle_local_position_setpoint", why, ("vx", "vy", "vz"))
    time_s = log.time_s("vehicle_local_position_setpoint")
    # from the arming: the set-point of a take-off starts moving before the lift-off
    armed = log.armed_span()
    inside = (time_s >= armed[0]) & (time_s <= armed[1])
    if np.count_nonzero(np.isfinite(np.asarray(data["vz"], float)[inside])) < 2:
        reason = (
            "no velocity set-point in the air (vehicle_local_position_setpoint is not "
            "logged there: the vehicle was not flown in a velocity-controlled mode)"
        )
        return [], [NotScorable(name="velocity_steps", kind="time", reason=reason)]
    time_s = time_s[inside]
    north, east, down = (np.asarray(data[f], float)[inside] for f in ("vx", "vy", "vz"))
    tests: list[PlannedTest] = []
    skipped: list[NotScorable] = []
    vertical = steps(time_s, down, VELOCITY_STEP)
    climbs = [s for s in vertical if s.change < 0 and s.end_s > airborne[0]]
    descents = [s for s in vertical if s.change > 0 and s.start_s < airborne[1]]
    for name, chosen, what in (("takeoff_climb_vz", climbs[:1], "climb after lift-off"),
                               ("landing_descent_vz", descents[-1:], "descent before "
                                                                     "touch-down")):  # fmt: skip
        if not chosen:
            reason = f"no vz set-point step of ≥ {VELOCITY_STEP.min_change:g} m/s ({what})"
            skipped.append(NotScorable(name=name, kind="time", reason=reason))
            continue
        segment = _segment(chosen, VELOCITY_STEP, airborne)
        found = f"{what.capitalize()}: vz set-point {_describe(chosen, 'm/s')} (NED, down +)."
        tests.append(PlannedTest(name, "time", found, _time_test(
            "vehicle_local_position.vz", segment, "m/s", 0.5)))  # fmt: skip
    valid = log.topics.get("vehicle_local_position", {}).get("v_xy_valid")
    if valid is not None and not np.any(np.asarray(valid) > 0.5):
        reason = (
            "no horizontal velocity: vehicle_local_position.v_xy_valid is 0 all flight "
            "(no GNSS or other horizontal aid), so vx, vy are not a measurement"
        )
        skipped.append(NotScorable(name="level_flight", kind="time", reason=reason))
        return tests, skipped
    heading = np.interp(time_s, *log.series("vehicle_local_position", "heading", why))
    forward, right = heading_frame(north, east, heading)
    frames = {
        "ned": (("vx", north), ("vy", east)),
        "heading": (("v_forward", forward), ("v_right", right)),
    }
    level = []
    for frame, axes in frames.items():
        for axis, values in axes:
            for step in steps(time_s, values, VELOCITY_STEP):
                mode = _nav_state_at(log, step.start_s)
                in_heading_frame = mode in HEADING_FRAME_MODES
                airborne_now = airborne[0] <= step.start_s <= airborne[1]
                if (airborne_now and abs(step.before) <= HOVER_SPEED_MPS
                        and in_heading_frame == (frame == "heading")):  # fmt: skip
                    level.append((step, axis, mode))
    # the axis that carries most of a manoeuvre first: the other one is skipped below
    level.sort(key=lambda item: -abs(item[0].change))
    taken: list[tuple[float, float]] = []
    level_tests: list[PlannedTest] = []
    for step, axis, mode in level:
        if any(step.start_s < end and start < step.end_s for start, end in taken):
            continue  # the same manoeuvre seen on the other axis of its frame
        taken.append((step.start_s, step.end_s))
        segment = _segment([step], VELOCITY_STEP, airborne)
        frame_text = (
            "along the heading frame (Position mode: the sticks' axes)"
            if axis.startswith("v_")
            else "in NED (an autopilot mode's path)"
        )
        found = (f"Hover → level flight in nav_state {mode}: {axis} set-point "
                 f"{_describe([step], 'm/s')}, {frame_text}.")  # fmt: skip
        level_tests.append(PlannedTest(f"level_flight_{axis}_{step.start_s:.0f}s", "time", found,
                                 _time_test(f"vehicle_local_position.{axis}", segment, "m/s",
                                            0.5)))  # fmt: skip
    tests += sorted(level_tests, key=lambda test: test.keys["segment_s"])
    if not taken:
        reason = (
            f"no horizontal velocity set-point step of ≥ {VELOCITY_STEP.min_change:g} "
            f"m/s from a hover (|v| ≤ {HOVER_SPEED_MPS:g} m/s)"
        )
        skipped.append(NotScorable(name="level_flight", kind="time", reason=reason))
    return tests, skipped


def position_steps(log: FlightLog, airborne: tuple[float, float]) -> list[PlannedTest]:
    """Steps of the position set-point in the air (POSITION_STEP: a goto handed to the
    position loop as it is), each scored on the velocity along its axis (NED): the level
    flight the step commands, which a replay reproduces where its position may have drifted
    (the reference autopilot replays velocity set-points, open loop on position)."""
    why = "position set-point steps"
    data = log.topic("vehicle_local_position_setpoint", why, ("x", "y", "z"))
    time_s = log.time_s("vehicle_local_position_setpoint")
    tests = []
    for axis in ("x", "y", "z"):
        for step in steps(time_s, np.asarray(data[axis], float), POSITION_STEP):
            if not airborne[0] <= step.start_s <= airborne[1] - POSITION_STEP.settle_s:
                continue
            segment = _segment([step], POSITION_STEP, airborne)
            found = (f"Position step: {axis} set-point {_describe([step], 'm')} (NED), "
                     f"handed to the position loop unsmoothed; scored on v{axis}.")  # fmt: skip
            tests.append(PlannedTest(f"position_step_{axis}_{step.start_s:.0f}s", "time", found,
                                     _time_test(f"vehicle_local_position.v{axis}", segment,
                                                "m/s", 0.5)))  # fmt: skip
    return sorted(tests, key=lambda test: test.keys["segment_s"])


def step_tests(log: FlightLog) -> Found:
    """Every step response the flight holds; a log never airborne has none."""
    try:
        airborne = log.airborne_span()
    except LogError as error:
        reason = f"no flight dynamics: {_without_path(error)}"
        return [], [NotScorable(name="step_responses", kind="time", reason=reason)]
    tests: list[PlannedTest] = []
    skipped: list[NotScorable] = []
    try:
        attitude = attitude_steps(log, airborne)
    except LogError as error:
        attitude = []
        skipped.append(NotScorable(name="attitude_steps", kind="time",
                                   reason=_without_path(error)))  # fmt: skip
    else:
        if not attitude:
            reason = (
                f"no roll or pitch set-point change of ≥ {ATTITUDE_STEP.min_change:g}° "
                f"within {ATTITUDE_STEP.max_rise_s:g} s in the air"
            )
            skipped.append(NotScorable(name="attitude_steps", kind="time", reason=reason))
    tests += attitude
    try:
        more, less = velocity_steps(log, airborne)
    except LogError as error:
        more, less = [], [NotScorable(name="velocity_steps", kind="time",
                                      reason=_without_path(error))]  # fmt: skip
    try:
        position = position_steps(log, airborne)
    except LogError as error:
        position = []
        skipped.append(NotScorable(name="position_steps", kind="time",
                                   reason=_without_path(error)))  # fmt: skip
    else:
        if not position:
            reason = (
                f"no position set-point step of ≥ {POSITION_STEP.min_change:g} m within "
                f"{POSITION_STEP.max_rise_s:g} s in the air (PX4 smooths its set-points: "
                "its steps are the velocity ones)"
            )
            skipped.append(NotScorable(name="position_steps", kind="time", reason=reason))
    return tests + more + position, skipped + less


# --- frequency responses (η_f) --------------------------------------------------------------


def pilot_spans(log: FlightLog) -> list[tuple[float, float]]:
    """Airborne spans flown in pilot modes (PILOT_MODES) of at least MIN_EXCITATION_S, at
    least GROUND_S from the lift-off and the touch-down: the pilot's stick inputs are the
    only broadband excitation of a flight without a sweep. (start, end), the most excited
    first (the highest RMS of the roll and pitch rate set-points: larger inputs stand
    further above the noise)."""
    airborne = log.airborne_span()
    time_s, mode = log.series("vehicle_status", "nav_state", "flight modes")
    spans = []
    piloted = np.isin(mode.astype(int), list(PILOT_MODES)).astype(float)
    for start, end, state in runs(time_s, piloted, log.last_s):
        start, end = max(start, airborne[0] + GROUND_S), min(end, airborne[1] - GROUND_S)
        if state and end - start >= MIN_EXCITATION_S:
            spans.append(_span(start, end))
    time_s, roll = log.series("vehicle_rates_setpoint", "roll", "pilot's inputs")
    pitch = log.series("vehicle_rates_setpoint", "pitch", "pilot's inputs")[1]

    def excitation(span: tuple[float, float]) -> float:
        inside = (time_s >= span[0]) & (time_s <= span[1])
        return float(np.sqrt(np.mean(roll[inside] ** 2 + pitch[inside] ** 2)))

    return sorted(spans, key=excitation, reverse=True)


def logged_rate_hz(log: FlightLog, topic: str) -> float:
    """The rate the logger wrote ``topic`` at (Hz, whole): its samples over its span. Each
    interval jitters around the logger's period (the X500's body rates: median 21 ms for a
    20 ms period), the mean does not."""
    time_s = log.time_s(topic)
    return float(round((time_s.size - 1) / float(time_s[-1] - time_s[0])))


def _uniform(log: FlightLog, path: str, grid: NDArray[np.float64]) -> NDArray[np.float64]:
    topic, field = path.split(".", 1)
    time_s, values = log.series(topic, field, "frequency response")
    return np.interp(grid, time_s, values)


def coherent_band(
    freqs_hz: NDArray[np.float64], coherence: NDArray[np.float64], minimum: float
) -> tuple[float, float] | None:
    """The widest band from one coherent grid point (γ² ≥ ``minimum``) to another in which
    at least COHERENT_SHARE of the points are coherent; None below MIN_BAND_RATIO.

    A dip below the threshold inside the band does not end it: the scoring leaves out
    each incoherent point and the report lists it, so the band keeps the coherent
    frequencies on both sides of a dip (x500_validation.toml's 0.2-3 Hz, mean γ² 0.55 over
    1-3 Hz in roll)."""
    coherent = coherence >= minimum
    share = np.concatenate(([0], np.cumsum(coherent)))
    best: tuple[float, float] | None = None
    for first in np.flatnonzero(coherent):
        for last in np.flatnonzero(coherent[first:]) + first:
            if share[last + 1] - share[first] < COHERENT_SHARE * (last + 1 - first):
                continue
            band = (float(freqs_hz[first]), float(freqs_hz[last]))
            if best is None or band[1] / band[0] > best[1] / best[0]:
                best = band
    if best is None or best[1] / best[0] < MIN_BAND_RATIO:
        return None
    return best


def response_tests(log: FlightLog) -> Found:
    """rate_sp → rate and torque_sp → rate per axis over the most excited pilot-flown span,
    each over the band where its coherence reaches the plan's ``coherence_min``
    (:func:`coherent_band`, from :func:`credibility.spectral.estimate_response`)."""
    try:
        spans = pilot_spans(log)
        sample_rate = min(logged_rate_hz(log, topic) for topic in RATE_TOPICS)
    except LogError as error:
        reason = f"no flight dynamics: {_without_path(error)}"
        return [], [NotScorable(name="frequency_responses", kind="frequency", reason=reason)]
    if not spans:
        reason = (f"no airborne span of ≥ {MIN_EXCITATION_S:g} s in a pilot-flown mode "
                  "(nav_state Manual, Altitude, Position, Acro or Stabilized): no broadband "
                  "excitation without a sweep")  # fmt: skip
        return [], [NotScorable(name="frequency_responses", kind="frequency", reason=reason)]
    start, end = spans[0]
    # the longest window half the span: three averages at 50 % overlap
    windows = tuple(math.floor((end - start) / 2**k * 100) / 100 for k in (4, 3, 2, 1))
    grid = np.arange(start, end, 1.0 / sample_rate)
    top_hz = BAND_TOP_NYQUIST * sample_rate / 2
    lowest_hz = math.ceil(spectral.MIN_CYCLES / windows[-1] * 100) / 100
    freqs = np.geomspace(lowest_hz, top_hz, COHERENCE_GRID_POINTS)
    minimum = indices.DEFAULT_COHERENCE_MIN
    tests: list[PlannedTest] = []
    skipped: list[NotScorable] = []
    for name, input_path, output_path, caveat in RESPONSES:
        try:
            estimate = spectral.estimate_response(
                _uniform(log, input_path, grid), _uniform(log, output_path, grid),
                sample_rate, freqs, windows)  # fmt: skip
        except (LogError, CredibilityError) as error:
            skipped.append(NotScorable(name=name, kind="frequency", reason=_without_path(error)))
            continue
        band = coherent_band(freqs, estimate.coherence, minimum)
        if band is None:
            reason = (f"{input_path} → {output_path}: no octave between {lowest_hz:g} and "
                      f"{top_hz:g} Hz with γ² ≥ {minimum:g} at {COHERENT_SHARE:.0%} of it "
                      f"over the pilot's inputs {start:.2f}-{end:.2f} s: too little "
                      "excitation on this axis")  # fmt: skip
            skipped.append(NotScorable(name=name, kind="frequency", reason=reason))
            continue
        in_band = (freqs >= band[0]) & (freqs <= band[1])
        share = float(np.mean(estimate.coherence[in_band] >= minimum))
        band = (round(band[0], 2), round(band[1], 2))
        found = (
            f"Pilot's inputs, {start:.2f}-{end:.2f} s (the pilot-flown span with the "
            f"largest rate set-points): γ² ≥ {minimum:g} at {share:.0%} of the grid "
            f"over {band[0]:g}-{band[1]:g} Hz (the widest band at least "
            f"{COHERENT_SHARE:.0%} coherent; logged at {sample_rate:g} Hz). {caveat}"
        ).strip()
        keys = {"kind": "frequency", "input": input_path, "output": output_path,
                "segment_s": (start, end), "sample_rate_hz": sample_rate,
                "band_hz": band, "windows_s": windows, "n_points": N_POINTS}  # fmt: skip
        tests.append(PlannedTest(name, "frequency", found, keys))
    return tests, skipped


# --- what no finder can plan from a log's content ---------------------------------------------


def log_limits(log: FlightLog) -> list[NotScorable]:
    """What the log's topics and rates rule out whatever the flight: a band above the rate
    topics' Nyquist frequency, rotor speeds without esc_status."""
    limits = []
    if all(topic in log.topics for topic in RATE_TOPICS):
        rate = min(logged_rate_hz(log, topic) for topic in RATE_TOPICS)
        reason = (
            f"the rate and torque topics are logged at {rate:g} Hz: nothing above the "
            f"{rate / 2:g} Hz Nyquist frequency"
        )
        limits.append(NotScorable(name=f"response_above_{rate / 2:g}_hz", kind="frequency",
                                  reason=reason))  # fmt: skip
    if "esc_status" not in log.topics:
        reason = "no esc_status in the log: the rotor speeds were not measured, only commanded"
        limits.append(NotScorable(name="rotor_speeds", kind="performance", reason=reason))
    return limits


def _without_path(error: Exception) -> str:
    """A LogError's message without the log's path, which the plan names once."""
    text = str(error)
    head, sep, rest = text.partition(": ")
    return rest if sep and head.endswith((".ulg", ".ULG")) else text


def describe(log: FlightLog) -> tuple[str, str]:
    """A name and a description from what the log says of itself: airframe, rotors,
    firmware and, when GNSS gave it, the date."""
    autostart = log.parameters.get("SYS_AUTOSTART")
    airframe = f"PX4 airframe {int(autostart)}" if autostart else "airframe not logged"
    rotors = int(log.parameters.get("CA_ROTOR_COUNT", 0))
    vehicle = f"{rotors}-rotor vehicle" if rotors else "vehicle"
    date = ""
    utc = log.topics.get("vehicle_gps_position", {}).get("time_utc_usec")
    if utc is not None and np.any(np.asarray(utc) > 0):
        stamp = float(np.asarray(utc)[np.asarray(utc) > 0][0]) / 1e6
        date = datetime.fromtimestamp(stamp, UTC).strftime("%Y-%m-%d")
    name = f"{vehicle.capitalize()} ({airframe}): automatic plan from {log.path.name}"
    description = (f"{vehicle.capitalize()}, {airframe}, {log.firmware}"
                   + (f", flown {date}" if date else "")
                   + f"; log {log.first_s:.1f}-{log.last_s:.1f} s. Segments found by "
                   "credibility plan; every test it could not plan is listed below "
                   "with the reason.")  # fmt: skip
    return name, description


def draft_plan(log: FlightLog) -> Draft:
    """Every test the log supports, and every one it does not with the reason."""
    tests: list[PlannedTest] = []
    skipped: list[NotScorable] = []
    for finder in (noise_tests, response_tests, step_tests):
        more, less = finder(log)
        tests += more
        skipped += less
    name, description = describe(log)
    return Draft(name, description, tuple(tests), tuple(skipped + log_limits(log)))


# --- the plan file ------------------------------------------------------------------------
# Written by hand: tomllib reads TOML but cannot write it, and a writer library would drop
# the comments that say what each segment is.


def _value(value: Any) -> str:
    """A TOML value: strings as JSON writes them (a TOML basic string), tables inline."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(round(value, 4))
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_value(v)}" for k, v in value.items()) + " }"
    return "[" + ", ".join(_value(v) for v in value) + "]"


def _comment(text: str) -> list[str]:
    return textwrap.wrap(text, 92, initial_indent="# ", subsequent_indent="# ")


def _relative(path: Path, start: Path) -> str:
    return Path(os.path.relpath(path.resolve(), start.resolve())).as_posix()


def plan_toml(draft: Draft, real: Path, sim: Path | None, plan_dir: Path) -> str:
    """The plan file's text; log paths relative to ``plan_dir``, where it will be written."""
    sim_text = _relative(sim, plan_dir) if sim is not None else SIM_PLACEHOLDER
    header = (
        f"Written by `credibility plan` from {real.name}: every segment below was found "
        "automatically, with what was found and by what criterion above each test. Edit it "
        "freely; `credibility report PLAN --log sim=RUN.ulg` scores a simulation with it."
    )
    if sim is None:
        header += (
            f" [logs] sim is a placeholder ({SIM_PLACEHOLDER}): point it at your simulation's "
            "log, or pass --log sim=PATH."
        )
    lines = _comment(header)
    lines += [
        "",
        "[plan]",
        f"name = {_value(draft.name)}",
        f"description = {_value(draft.description)}",
        f"pass_mark = {indices.DEFAULT_PASS_MARK}",
        "# ε_min = the pass mark: a first model from one flight rarely reaches the paper's 0.9.",
        f"eps_min = {EPS_MIN}",
        f"k_p = {indices.DEFAULT_K_P}",
        f"max_gap_s = {MAX_GAP_S}",
        "",
        "# The paper's weights (section 4.2.4) over the kinds this plan holds, summing to 1.",
        "[weights]",
        *(f"{kind} = {alpha}" for kind, alpha in draft.weights.items()),
        "",
        "[logs]",
        f"real = {_value(_relative(real, plan_dir))}",
        f"sim = {_value(sim_text)}",
    ]
    for test in draft.tests:
        lines += ["", *_comment(test.found), "[[tests]]", f"name = {_value(test.name)}"]
        lines += [f"{key} = {_value(value)}" for key, value in test.keys.items()]
    for item in draft.not_scorable:
        lines += ["", "[[not_scorable]]", f"name = {_value(item.name)}",
                  f"kind = {_value(item.kind)}", f"reason = {_value(item.reason)}"]  # fmt: skip
    return "\n".join(lines) + "\n"


def write_plan(log: FlightLog, out: Path, sim: Path | None = None) -> Draft:
    """Find the plan in ``log`` and write it to ``out``; a log that supports no test is one
    line with every reason."""
    draft = draft_plan(log)
    if not draft.tests:
        reasons = "; ".join(f"{item.name}: {item.reason}" for item in draft.not_scorable)
        raise CredibilityError(f"{log.path}: no test can be planned from this log ({reasons})")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(plan_toml(draft, log.path, sim, out.parent), encoding="utf-8")
    return draft
