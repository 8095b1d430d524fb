"""η_t: set-point steps and doublets (attitude, velocity, position), each scored on the
response it commands, from a little before the step to the settled response."""

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from credibility.autoplan.draft import Found, PlannedTest, span, without_path
from credibility.autoplan.responses import PILOT_MODES
from credibility.logs import euler_zyx, heading_frame
from credibility.plan import NotScorable
from px4_logs import FlightLog, LogError

#: Of those, the modes whose horizontal sticks command a velocity in the heading frame.
HEADING_FRAME_MODES = frozenset({2, 6})


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


def _segment(
    group: Sequence[Step], shape: StepShape, inside: tuple[float, float]
) -> tuple[float, float]:
    start = max(group[0].start_s - shape.lead_s, inside[0])
    end = min(group[-1].end_s + shape.settle_s, inside[1])
    return span(start, end)


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
        reason = f"no flight dynamics: {without_path(error)}"
        return [], [NotScorable(name="step_responses", kind="time", reason=reason)]
    attitude = _planned(lambda: attitude_steps(log, airborne), "attitude_steps",
                        f"no roll or pitch set-point change of ≥ {ATTITUDE_STEP.min_change:g}° "
                        f"within {ATTITUDE_STEP.max_rise_s:g} s in the air")  # fmt: skip
    try:
        velocity = velocity_steps(log, airborne)
    except LogError as error:
        velocity = [], [NotScorable(name="velocity_steps", kind="time",
                                    reason=without_path(error))]  # fmt: skip
    position = _planned(lambda: position_steps(log, airborne), "position_steps",
                        f"no position set-point step of ≥ {POSITION_STEP.min_change:g} m within "
                        f"{POSITION_STEP.max_rise_s:g} s in the air (PX4 smooths its "
                        "set-points: its steps are the velocity ones)")  # fmt: skip
    found = (attitude, velocity, position)
    return [t for tests, _ in found for t in tests], [n for _, skipped in found for n in skipped]


def _planned(find: Callable[[], list[PlannedTest]], name: str, none_found: str) -> Found:
    """A finder's tests, or why there are none: a topic the log lacks, or ``none_found``."""
    try:
        tests = find()
    except LogError as error:
        return [], [NotScorable(name=name, kind="time", reason=without_path(error))]
    return tests, [] if tests else [NotScorable(name=name, kind="time", reason=none_found)]
