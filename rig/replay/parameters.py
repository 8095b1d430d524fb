"""Which of a log's parameters the replay's autopilot takes: the reference autopilot's
known ones in range; PX4's by its build's parameter list; and what a log's PX4 learned in
flight that another PX4 release needs set."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from hil_config import FieldError
from rig.autopilots.px4 import (
    Px4NotFound,
    build_parameters,
    check_imu_rate,
    find_px4,
    sitl_parameters,
)
from rig.autopilots.reference.params import PARAMETERS, ParameterError, Parameters
from rig.errors import RigError
from rig.replay.options import ReplayError, ReplayOptions
from rig.replay.timeline import NAV_STATE_MISSION, FlightEvent, ReplayLog
from rig.scenarios.scenario import Rates

#: A PX4 replay's IMU (= lockstep) rate unless --imu-hz says otherwise is the log's
#: IMU_GYRO_RATEMAX, the rate its rate controller ran at (800 Hz on the X500), where PX4 can
#: keep lockstep at it; else this. At 250 Hz the rig's IMU (vibration sampled without the
#: real chips' 8 kHz filtering) left EKF2's vertical velocity 1-2 m/s off and the altitude
#: hold swinging ±2.5 m where the real one held; at 800 and 1000 Hz it follows the real flight.
PX4_IMU_HZ = Rates().imu_hz
#: Parameters the rig sets itself: MAV_SYS_ID follows the SITL instance.
RIG_OWNED_PARAMETERS = frozenset({"MAV_SYS_ID"})


#: nav_states whose heading PX4's auto planner sets (MPC_YAWRAUTO_*): Mission, Loiter,
#: Return, Takeoff, Land, Precision land.
AUTO_YAW_MODES = frozenset({3, 4, 5, 17, 18, 20})


#: The least yaw rate (°/s) a replay's schedule of MPC_YAWRAUTO_MAX allows, so that a
#: heading that differs from the real one at a turn's start can still converge.
YAW_RATE_LIMIT_FLOOR_DEG_S = 5.0


#: A schedule's new MPC_YAWRAUTO_MAX is sent when it differs from the last by this much (°/s).
YAW_RATE_LIMIT_STEP_DEG_S = 2.0


#: nav_states whose throttle is the pilot's stick, not a climb rate: Manual, Acro, Stabilized.
MANUAL_THRUST_MODES = frozenset({0, 10, 15})


#: What a PX4 replay takes from the flight where PX4 changed between versions, and why
#: (:func:`learned_parameters`).
_STICK_THRUST = "this SITL's stick → thrust map as the log's PX4 had it"


LEARNED = {
    "MPC_THR_HOVER": f"its hover_thrust_estimate, the centre stick's thrust in its PX4: "
    f"{_STICK_THRUST}",
    "MPC_MANTHR_MIN": f"its thrust set-point with the throttle stick at the bottom: "
    f"{_STICK_THRUST}",
    "MPC_YAWRAUTO_MAX": "its peak yaw rate in Mission, where its PX4 limited the yaw "
    "acceleration (MPC_YAWRAUTO_ACC, not in this build); in auto modes it then follows the "
    "yaw rate the real planner allowed itself (yaw_rate_limits in replay.json), so this "
    "SITL's turns start and end as the real ones did",
}


@dataclass(frozen=True)
class SkippedParameter:
    name: str
    value: float
    reason: str


def learned_parameters(
    log: ReplayLog, applied: Mapping[str, float], events: tuple[FlightEvent, ...]
) -> dict[str, float]:
    """The parameters that give this SITL the log's own behaviour where PX4 changed it
    between versions (the 8S quad's v1.16 and the X500's v1.17 against the v1.14 SITL).

    Where the replay flew a stick-throttle mode, the log's stick → thrust map:

    - MPC_THR_HOVER = the log's hover-thrust estimate when its PX4 ran on it (MPC_USE_HTE):
      v1.16 puts the centre stick there in Stabilized (0.655 in hover; its MPC_THR_HOVER is
      0.5), v1.14 at MPC_THR_HOVER; without it the centred stick gives the SITL 0.50 where
      the real one gave 0.66, and it never lifts. The estimate converges in the first seconds
      airborne, so its median over the flight is taken.
    - MPC_MANTHR_MIN = the log's thrust set-point with the stick at the bottom (0 there:
      armed, the motors stopped), which v1.14 holds at MPC_MANTHR_MIN (0.08: the SITL's
      rotors idled through the log's rest).

    In the climb-rate modes PX4 flies on its own estimate, so nothing is set there.

    Where it flew Mission and its PX4 limited the yaw acceleration in auto modes
    (MPC_YAWRAUTO_ACC, 20°/s² in the X500's v1.17) but this build has no such limit:

    - MPC_YAWRAUTO_MAX = the peak yaw rate the real vehicle reached in Mission (the X500's
      33.6°/s against its MPC_YAWRAUTO_MAX of 60). v1.14 turns at MPC_YAWRAUTO_MAX from
      the turn's start: it handed the X500's pilot a heading 73° from the real one at the
      take-over, 33° with the real peak rate as its limit."""
    learned = {}
    if any(e.commanded and e.nav_state in MANUAL_THRUST_MODES for e in events):
        estimate = log.hover_thrust()
        if (
            "MPC_THR_HOVER" in applied
            and log.parameters.get("MPC_USE_HTE")
            and estimate is not None
        ):
            learned["MPC_THR_HOVER"] = estimate
        bottom = log.thrust_at_bottom_stick()
        if "MPC_MANTHR_MIN" in applied and bottom is not None:
            learned["MPC_MANTHR_MIN"] = bottom
    if _yaw_acceleration_limited(log, applied):
        peak = log.peak_yaw_rate_deg_s(NAV_STATE_MISSION)
        if peak is not None and 0.0 < peak < applied["MPC_YAWRAUTO_MAX"]:
            learned["MPC_YAWRAUTO_MAX"] = round(peak, 1)
    return learned


def _yaw_acceleration_limited(log: ReplayLog, applied: Mapping[str, float]) -> bool:
    """The log's PX4 limited the yaw acceleration in auto modes, this SITL cannot."""
    return (
        "MPC_YAWRAUTO_ACC" in log.parameters
        and "MPC_YAWRAUTO_ACC" not in applied
        and "MPC_YAWRAUTO_MAX" in applied
    )


def yaw_rate_limits(
    log: ReplayLog, applied: Mapping[str, float], start_s: float, end_s: float
) -> tuple[tuple[float, float], ...]:
    """MPC_YAWRAUTO_MAX over the flight (log s, °/s) for a SITL without the log's yaw
    acceleration limit: in auto modes, the rate the real planner allowed itself.

    The log's PX4 (v1.17 on the X500) ramps a turn's yaw rate at MPC_YAWRAUTO_ACC (20°/s²);
    v1.14 turns at MPC_YAWRAUTO_MAX from the turn's first step. Its limit set to the real
    ``trajectory_setpoint.yawspeed`` (the larger of each sample and the next, so it never
    lags the real ramp) gives it the real turn. The real rate is followed only down to
    :data:`YAW_RATE_LIMIT_FLOOR_DEG_S`, and a new value is sent when it moved by
    :data:`YAW_RATE_LIMIT_STEP_DEG_S` (each is a PARAM_SET conversation)."""
    if not _yaw_acceleration_limited(log, applied):
        return ()
    limits: list[tuple[float, float]] = []
    for time_s, rates in log.auto_yaw_rates_deg_s(AUTO_YAW_MODES, start_s, end_s):
        envelope = np.maximum(rates, np.append(rates[1:], rates[-1]))
        for k, (sample_s, rate) in enumerate(zip(time_s, envelope, strict=True)):
            limit = round(max(float(rate), YAW_RATE_LIMIT_FLOOR_DEG_S), 1)
            if k == 0 or abs(limit - limits[-1][1]) >= YAW_RATE_LIMIT_STEP_DEG_S:
                limits.append((float(sample_s), limit))
    return tuple(limits)


def with_px4_imu_rate(options: ReplayOptions, logged: Mapping[str, float]) -> ReplayOptions:
    """Without --imu-hz, PX4 runs its rate loop at the log's IMU_GYRO_RATEMAX when it can
    keep lockstep there (PX4_IMU_HZ otherwise)."""
    if options.imu_hz is not None:
        return options
    rate = int(logged.get("IMU_GYRO_RATEMAX", 0))
    try:
        check_imu_rate(rate)
        Rates(imu_hz=rate)
    except (RigError, FieldError):
        rate = PX4_IMU_HZ
    return replace(options, imu_hz=rate)


def px4_parameters(
    logged: dict[str, float | int], options: ReplayOptions
) -> tuple[dict[str, float | int], tuple[SkippedParameter, ...], int]:
    """The log's parameters PX4 SITL takes, the skipped ones with why, and how many this
    build does not have; the build (--px4, $PX4_DIR) is needed for its parameter list."""
    try:
        build = find_px4(options.px4_dir)
        known = None if build is None else build_parameters(build)
    except Px4NotFound as error:
        raise ReplayError(str(error)) from None
    if known is None:
        raise ReplayError(
            "--autopilot px4 needs PX4's build (--px4 DIR or $PX4_DIR): its parameter list "
            "decides which of the log's parameters PX4 takes"
        )
    applied, skipped = sitl_parameters(logged, known)
    return (
        {name: logged[name] for name in applied},
        tuple(SkippedParameter(*entry) for entry in skipped),
        sum(1 for name in logged if name not in known),
    )


def reference_parameters(
    logged: dict[str, float | int],
) -> tuple[dict[str, float | int], tuple[SkippedParameter, ...], int]:
    """Split the log's parameters: applied (known and in range), skipped, unknown count."""
    known = {spec.name for spec in PARAMETERS} - RIG_OWNED_PARAMETERS
    check = Parameters()
    applied: dict[str, float | int] = {}
    skipped = []
    for name in sorted(logged):
        if name not in known:
            continue
        try:
            check.set(name, logged[name])
        except ParameterError as error:  # outside our range: reported, never clamped
            skipped.append(SkippedParameter(name, float(logged[name]), str(error)))
            continue
        applied[name] = logged[name]
    unknown = sum(1 for name in logged if name not in known and name not in RIG_OWNED_PARAMETERS)
    return applied, tuple(skipped), unknown
