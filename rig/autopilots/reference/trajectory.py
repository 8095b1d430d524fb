"""PX4's jerk-limited set-points for autonomous flight (take-off, hold, goto, mission).

PX4's ``FlightTaskAuto`` does not hand the position controller its target: a smoothed
trajectory runs towards it (``lib/motion_planning/PositionSmoothing`` over three
``VelocitySmoothing`` axes), and the controller tracks the trajectory's position with its
velocity and acceleration as feed-forward. Each axis changes its velocity time-optimally
under a jerk limit (``MPC_JERK_AUTO``) and an acceleration limit (``MPC_ACC_HOR``,
``MPC_ACC_UP_MAX``, ``MPC_ACC_DOWN_MAX``); the three are stretched to finish together, so
the path is straight. The velocity asked of them points at the target, at the speed from
which the trajectory can still stop on it (:func:`max_speed_from_distance`); near the
target that speed is about half the distance per second, which is why PX4 closes the last
metre of a take-off in a few seconds rather than at ``MPC_TKO_SPEED``.

Written from PX4's behaviour and equations (v1.14-v1.17 ``VelocitySmoothing.cpp``,
``PositionSmoothing.cpp``, ``TrajMath.hpp``); the code here is this project's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from quad_model.frames import euclidean_norm

#: Below this speed (m/s) a part of the velocity set-point is clipped alone (PX4's
#: ``clampToXYNorm``/``clampToZNorm`` accuracy).
_NEARLY_THERE_MPS = 0.5


def max_speed_from_distance(
    jerk: float, accel: float, distance: float, final_speed: float
) -> float:
    """The speed from which a jerk- and acceleration-limited brake reaches ``final_speed``
    within ``distance``: the positive root of ``v² + (4a²/j)·v - 2a·d - v_f² = 0``, a
    conservative bound (the braking's jerk phases counted as if at full deceleration)."""
    b = 4.0 * accel * accel / jerk
    c = -2.0 * accel * distance - final_speed * final_speed
    return max(0.5 * (-b + math.sqrt(b * b - 4.0 * c)), final_speed)


@dataclass(frozen=True)
class Limits:
    """What bounds the trajectory: speeds (m/s), accelerations (m/s²), jerk (m/s³)."""

    speed_xy: float
    speed_up: float
    speed_down: float
    accel_xy: float
    accel_up: float
    accel_down: float
    jerk: float
    #: ``MPC_XY_ERR_MAX``: the trajectory waits for a vehicle this far behind it (m).
    max_error_xy: float


#: One axis's (acceleration, velocity, position): plain floats, as PX4's own scalars (numpy
#: arrays of three cost the autopilot's 50 Hz position loop a third of its time).
_State = tuple[float, float, float]


class _Axis:
    """One axis: its velocity moves to a target velocity in three phases (jerk ±j, then
    none, then ∓j), each as short as the limits allow, or stretched to a given total."""

    def __init__(self) -> None:
        self.state: _State = (0.0, 0.0, 0.0)
        self._start: _State = (0.0, 0.0, 0.0)
        self._elapsed = 0.0
        self._phases = (0.0, 0.0, 0.0)
        self._jerk = 0.0

    def reset(self, accel: float, velocity: float, position: float) -> None:
        self.state = self._start = (accel, velocity, position)
        self._elapsed = 0.0
        self._phases = (0.0, 0.0, 0.0)

    @property
    def total_s(self) -> float:
        return sum(self._phases)

    def advance(self, dt_s: float) -> None:
        """Move along the planned phases by ``dt_s``, then coast at constant velocity."""
        self._elapsed += dt_s
        remaining = self._elapsed
        state = self._start
        for duration, jerk in zip(self._phases, (self._jerk, 0.0, -self._jerk), strict=True):
            t = min(remaining, duration)
            state = _evaluate(state, jerk, t)
            remaining -= t
        if remaining > 0.0:
            state = _evaluate((0.0, state[1], state[2]), 0.0, remaining)
        self.state = state

    def plan(self, velocity_sp: float, max_speed: float, max_accel: float, max_jerk: float,
             total_s: float | None = None) -> None:  # fmt: skip
        """Plan from the current state to ``velocity_sp`` (clipped to ``max_speed``): in the
        least time, or in ``total_s`` when another axis takes longer."""
        accel, velocity, _ = self.state
        self._start, self._elapsed = self.state, 0.0
        target = min(max(velocity_sp, -max_speed), max_speed)
        # The velocity reached by bringing the acceleration to zero now decides the sign.
        coast = velocity + accel * abs(accel) / (2.0 * max_jerk)
        direction = math.copysign(1.0, target - coast) if target != coast else math.copysign(
            1.0, accel) if accel else 0.0  # fmt: skip
        if direction == 0.0:
            self._phases, self._jerk = (0.0, 0.0, 0.0), 0.0
            return
        jerk = direction * max_jerk
        dv = target - velocity
        if total_s is None:
            t1 = _first_phase_fastest(accel, dv, jerk)
        else:
            t1 = _first_phase_given_total(total_s, accel, dv, jerk)
        t1 = _saturate_for_accel(accel, jerk, t1, max_accel)
        t3 = max(accel / jerk + t1, 0.0)
        if total_s is None:
            peak = accel + jerk * t1
            t2 = 0.0
            if abs(peak) > 1e-9:
                t2 = (
                    dv - accel * t1 - 0.5 * jerk * t1 * t1 - peak * t3 + 0.5 * jerk * t3 * t3
                ) / peak
            t2 = max(t2, 0.0)
        else:
            t2 = max(total_s - t1 - t3, 0.0)
        self._phases, self._jerk = (t1, t2, t3), jerk


def _evaluate(state: _State, jerk: float, t: float) -> _State:
    accel, velocity, position = state
    return (
        accel + jerk * t,
        velocity + accel * t + 0.5 * jerk * t * t,
        position + velocity * t + 0.5 * accel * t * t + jerk * t**3 / 6.0,
    )


def _first_phase_fastest(accel: float, dv: float, jerk: float) -> float:
    """Jerk time of the fastest change by ``dv`` ending at zero acceleration (no cruise)."""
    delta = 2.0 * accel * accel + 4.0 * jerk * dv
    if delta < 0.0:
        return 0.0
    for t1 in ((-accel + 0.5 * math.sqrt(delta)) / jerk, (-accel - 0.5 * math.sqrt(delta)) / jerk):
        if t1 >= 0.0 and accel / jerk + t1 >= 0.0:
            return t1
    return 0.0


def _first_phase_given_total(total_s: float, accel: float, dv: float, jerk: float) -> float:
    """Jerk time of a change by ``dv`` that takes ``total_s`` in all."""
    delta = (total_s * jerk) ** 2 + 2.0 * total_s * accel * jerk - accel * accel - 4.0 * jerk * dv
    if delta < 0.0:
        return 0.0
    b = jerk * total_s - accel
    for t1 in ((-b + math.sqrt(delta)) / (-2.0 * jerk), (-b - math.sqrt(delta)) / (-2.0 * jerk)):
        t1 = max(t1, 0.0)
        t3 = accel / jerk + t1
        if t3 >= 0.0 and t1 + t3 <= total_s:
            return t1
    return 0.0


def _saturate_for_accel(accel: float, jerk: float, t1: float, max_accel: float) -> float:
    peak = accel + jerk * t1
    if peak > max_accel:
        return (max_accel - accel) / jerk
    if peak < -max_accel:
        return (-max_accel - accel) / jerk
    return t1


class PositionSmoothing:
    """The trajectory PX4's auto modes fly towards one target (see the module doc)."""

    def __init__(self) -> None:
        self._axes = (_Axis(), _Axis(), _Axis())

    def reset(self, position: NDArray[np.float64], velocity: NDArray[np.float64]) -> None:
        for axis, p, v in zip(self._axes, position, velocity, strict=True):
            axis.reset(0.0, float(v), float(p))

    @property
    def position(self) -> NDArray[np.float64]:
        return np.array([axis.state[2] for axis in self._axes])

    @property
    def velocity(self) -> NDArray[np.float64]:
        return np.array([axis.state[1] for axis in self._axes])

    @property
    def acceleration(self) -> NDArray[np.float64]:
        return np.array([axis.state[0] for axis in self._axes])

    def update(self, target: NDArray[np.float64], vehicle: NDArray[np.float64], dt_s: float,
               limits: Limits) -> None:  # fmt: skip
        """Advance ``dt_s`` (slower while the vehicle lags the trajectory horizontally,
        stopped at ``max_error_xy`` behind it), then plan towards ``target``."""
        x, y, _ = self._axes
        behind_x, behind_y = x.state[2] - float(vehicle[0]), y.state[2] - float(vehicle[1])
        stretch = 1.0
        if limits.max_error_xy > 0.0 and behind_x * x.state[1] + behind_y * y.state[1] >= 0.0:
            stretch = 1.0 - min(euclidean_norm(behind_x, behind_y) / limits.max_error_xy, 1.0)
        for axis in self._axes:
            axis.advance(dt_s * stretch)
        offset = [float(t) - axis.state[2] for t, axis in zip(target, self._axes, strict=True)]
        up = offset[2] < 0.0
        accel_z, speed_z = (limits.accel_up, limits.speed_up) if up else (
            limits.accel_down, limits.speed_down)  # fmt: skip
        distance_xy = euclidean_norm(offset[0], offset[1])
        speed_xy = min(limits.speed_xy, max_speed_from_distance(
            limits.jerk, limits.accel_xy, distance_xy, 0.0))  # fmt: skip
        speed_z = min(speed_z, max_speed_from_distance(limits.jerk, accel_z, abs(offset[2]), 0.0))
        norm = euclidean_norm(*offset)
        speed = math.hypot(speed_xy, speed_z)
        velocity_sp = [0.0, 0.0, 0.0] if norm < 1e-6 else [o / norm * speed for o in offset]
        for bound, part in ((speed_xy, (0, 1)), (speed_z, (2,))):
            size = euclidean_norm(*(velocity_sp[i] for i in part))
            if size > bound:
                # The whole vector, so the path stays straight; a part that is nearly
                # there (both under 0.5 m/s) alone, so it cannot stall the other.
                near = bound < _NEARLY_THERE_MPS and size < _NEARLY_THERE_MPS
                for i in part if near else (0, 1, 2):
                    velocity_sp[i] *= bound / size
        accels = (limits.accel_xy, limits.accel_xy, accel_z)
        speeds = (limits.speed_xy, limits.speed_xy, speed_z)
        for axis, v, a, s in zip(self._axes, velocity_sp, accels, speeds, strict=True):
            axis.plan(v, s, a, limits.jerk)
        longest = max(axis.total_s for axis in self._axes)
        for axis, v, a, s in zip(self._axes, velocity_sp, accels, speeds, strict=True):
            if 1e-9 < axis.total_s < longest:
                axis.plan(v, s, a, limits.jerk, longest)
