"""A pilot's sticks: PX4's Position and Altitude modes and its take-off from the sticks.

PX4 facts used here (PX4-Autopilot v1.14, ``src/modules/flight_mode_manager/tasks/``):

- ``Utility/Sticks``: ``manual_control_setpoint`` (roll, pitch, yaw −1..1, throttle −1 at
  idle) shaped by ``math::expo_deadzone`` (``src/lib/mathlib/math/Functions.hpp``) with
  ``MPC_HOLD_DZ`` and ``MPC_XY_MAN_EXPO`` / ``MPC_Z_MAN_EXPO`` / ``MPC_YAW_EXPO``;
- ``ManualAltitude``: the throttle stick is a vertical speed up to ``MPC_Z_VEL_MAX_UP`` /
  ``MPC_Z_VEL_MAX_DN``, the height locked once the stick is centred and the vehicle slower
  than ``MPC_HOLD_MAX_Z``, slowed near the ground (``MPC_LAND_ALT1/2``,
  ``MPC_LAND_SPEED``, ``MPC_TKO_SPEED``); horizontal sticks tilt the vehicle
  (``Utility/StickTiltXY``: ``MPC_MAN_TILT_MAX``, ``MC_MAN_TILT_TAU``); the take-off is
  wanted with the throttle stick above 0.3;
- ``ManualPosition`` (``MPC_POS_MODE`` 0, direct velocity): the horizontal sticks are a
  velocity up to ``MPC_VEL_MANUAL`` in the heading frame, the position locked once they
  are centred and the vehicle slower than ``MPC_HOLD_MAX_XY``;
- ``Utility/StickYaw``: the yaw stick is a yaw rate up to ``MPC_MAN_Y_MAX``, low-passed
  by ``MPC_MAN_Y_TAU``, the heading held when it is centred;
- ``mc_pos_control/Takeoff``: from the ground the upward speed limit ramps from
  −g / ``MPC_Z_VEL_P_ACC`` (no thrust at all) to the climb asked for over
  ``MPC_TKO_RAMP_T``.

The task yields a :class:`~rig.autopilots.reference.navigator.Setpoint` for the same
position and velocity cascade as every other mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from quad_model.frames import STANDARD_GRAVITY_MPS2
from rig.autopilots.reference.navigator import Setpoint
from rig.autopilots.reference.params import Parameters

#: PX4 ``FlightTaskManualAltitude::_checkTakeoff``: the throttle stick above this asks to
#: take off.
TAKEOFF_THROTTLE = 0.3
#: PX4 ``FLT_EPSILON``: a shaped stick below it counts as centred.
_EPSILON = float(np.finfo(np.float32).eps)
#: PX4 ``FlightTaskManualAltitude::_isYawInput``: the filtered yaw rate counts as input
#: above this (rad/s).
_YAW_INPUT_RADPS = 0.001


@dataclass(frozen=True)
class Sticks:
    """PX4's ``manual_control_setpoint``, received at ``time_us``: roll (+1 right), pitch
    (+1 forward), yaw (+1 clockwise) −1..1 and throttle −1 (idle) .. 1."""

    roll: float
    pitch: float
    yaw: float
    throttle: float
    time_us: int


def sticks_from_manual_control(x: int, y: int, z: int, r: int, time_us: int) -> Sticks:
    """MANUAL_CONTROL as PX4's ``mavlink_receiver`` reads it: pitch ``x``, roll ``y`` and yaw
    ``r`` in ±1000, throttle ``z`` in 0..1000 read as z/500 − 1; held at the stops."""

    def axis(value: float) -> float:
        return min(max(value, -1.0), 1.0)

    return Sticks(
        roll=axis(y / 1000), pitch=axis(x / 1000), yaw=axis(r / 1000),
        throttle=axis(z / 500 - 1), time_us=time_us,
    )  # fmt: skip


def deadzone(value: float, dz: float) -> float:
    """PX4 ``math::deadzone``: zero within ±dz, linear and continuous outside, ±1 at ±1."""
    x = min(max(value, -1.0), 1.0)
    dzc = min(max(dz, 0.0), 0.99)
    if abs(x) <= dzc:
        return 0.0
    return (x - math.copysign(dzc, x)) / (1.0 - dzc)


def expo(value: float, e: float) -> float:
    """PX4 ``math::expo``: (1 − e)·x + e·x³, e in 0..1."""
    x = min(max(value, -1.0), 1.0)
    ec = min(max(e, 0.0), 1.0)
    return (1.0 - ec) * x + ec * x**3


def expo_deadzone(value: float, e: float, dz: float) -> float:
    """PX4 ``math::expo_deadzone``: the deadzone, then the expo."""
    return expo(deadzone(value, dz), e)


def _alpha(dt_s: float, tau_s: float) -> float:
    """PX4 ``AlphaFilter::setParameters(dt, tau)``: the low-pass's weight of a new sample."""
    return dt_s / (tau_s + dt_s)


class ManualTask:
    """PX4's ``FlightTaskManualPosition`` (``position_mode``) or ``FlightTaskManualAltitude``,
    with mc_pos_control's take-off ramp."""

    def __init__(self, params: Parameters) -> None:
        self.params = params
        self.position_mode = True
        self.position_sp = np.full(3, np.nan)
        self.yaw_sp_rad = math.nan
        self.yawspeed_radps = 0.0
        self._tilt_stick = np.zeros(2)
        #: Take-off ramp progress 0..1; 1: flying.
        self.ramp_progress = 1.0

    def activate(
        self, position_ned_m: NDArray[np.float64], position_mode: bool, on_ground: bool
    ) -> None:
        """Enter the mode where the vehicle is: height (and position) held, heading locked at
        the next update; the take-off ramp starts over when ``on_ground``."""
        self.position_mode = position_mode
        self.position_sp = np.array(position_ned_m, dtype=float)
        if not position_mode:
            self.position_sp[:2] = np.nan
        self.yaw_sp_rad = math.nan
        self.yawspeed_radps = 0.0
        self._tilt_stick = np.zeros(2)
        self.ramp_progress = 0.0 if on_ground else 1.0

    @staticmethod
    def wants_takeoff(sticks: Sticks) -> bool:
        return sticks.throttle > TAKEOFF_THROTTLE

    def update(
        self,
        sticks: Sticks,
        position_ned_m: NDArray[np.float64],
        velocity_ned_mps: NDArray[np.float64],
        yaw_rad: float,
        height_above_ground_m: float,
        dt_s: float,
    ) -> Setpoint:
        """One position-loop step: the sticks → the set-point (NaN: not controlled)."""
        p = self.params
        dz = p["MPC_HOLD_DZ"]
        # yaw (StickYaw): a rate, the heading locked once the filtered rate is gone
        yaw_stick = expo_deadzone(sticks.yaw, p["MPC_YAW_EXPO"], dz)
        yaw_rate = yaw_stick * math.radians(p["MPC_MAN_Y_MAX"])
        self.yawspeed_radps += _alpha(dt_s, p["MPC_MAN_Y_TAU"]) * (yaw_rate - self.yawspeed_radps)
        if abs(self.yawspeed_radps) > _YAW_INPUT_RADPS:
            self.yaw_sp_rad = math.nan
        elif not math.isfinite(self.yaw_sp_rad):
            self.yaw_sp_rad = yaw_rad
        heading = self.yaw_sp_rad if math.isfinite(self.yaw_sp_rad) else yaw_rad
        c, s = math.cos(heading), math.sin(heading)

        # vertical (ManualAltitude): throttle up is NED up
        z_stick = expo_deadzone(-sticks.throttle, p["MPC_Z_MAN_EXPO"], dz)
        speed_up, speed_down = p["MPC_Z_VEL_MAX_UP"], p["MPC_Z_VEL_MAX_DN"]
        velocity_sp = np.full(3, np.nan)
        velocity_sp[2] = (speed_down if z_stick > 0.0 else speed_up) * z_stick
        centred = abs(z_stick) <= _EPSILON
        if not centred:
            self.position_sp[2] = np.nan
        elif (
            not math.isfinite(self.position_sp[2])
            and abs(velocity_ned_mps[2]) < p["MPC_HOLD_MAX_Z"]
        ):
            self.position_sp[2] = position_ned_m[2]
        # the ground slowdown, by the height above the ground
        alt2, alt1 = p["MPC_LAND_ALT2"], p["MPC_LAND_ALT1"]
        near = min(max((height_above_ground_m - alt2) / max(alt1 - alt2, 1e-3), 0.0), 1.0)
        limit_down = p["MPC_LAND_SPEED"] + near * (speed_down - p["MPC_LAND_SPEED"])
        limit_up = p["MPC_TKO_SPEED"] + near * (speed_up - p["MPC_TKO_SPEED"])
        velocity_sp[2] = min(max(velocity_sp[2], -limit_up), limit_down)

        acceleration_sp = np.zeros(3)
        stick_xy = np.array([sticks.pitch, sticks.roll])
        if self.position_mode:  # ManualPosition: a velocity, the position locked
            xy = np.array([expo_deadzone(v, p["MPC_XY_MAN_EXPO"], dz) for v in stick_xy])
            xy /= max(float(np.hypot(*xy)), 1.0)
            velocity_sp[:2] = p["MPC_VEL_MANUAL"] * np.array(
                [c * xy[0] - s * xy[1], s * xy[0] + c * xy[1]]
            )
            brake = float(np.hypot(*velocity_sp[:2])) < _EPSILON
            stopped = float(np.hypot(*velocity_ned_mps[:2])) < p["MPC_HOLD_MAX_XY"]
            if not brake:
                self.position_sp[:2] = np.nan
            elif stopped and not np.isfinite(self.position_sp[:2]).all():
                self.position_sp[:2] = position_ned_m[:2]
        else:  # ManualAltitude: a tilt (StickTiltXY), as an acceleration
            stick_xy /= max(float(np.hypot(*stick_xy)), 1.0)
            self._tilt_stick += _alpha(dt_s, p["MC_MAN_TILT_TAU"]) * (stick_xy - self._tilt_stick)
            tilt = self._tilt_stick
            scale = math.tan(math.radians(p["MPC_MAN_TILT_MAX"])) * STANDARD_GRAVITY_MPS2
            acceleration_sp[:2] = scale * np.array(
                [c * tilt[0] - s * tilt[1], s * tilt[0] + c * tilt[1]]
            )
        limits = (p["MPC_VEL_MANUAL"], self._ramp(dt_s, speed_up), speed_down)
        return Setpoint(
            self.position_sp.copy(), velocity_sp, heading, self.yawspeed_radps, limits,
            acceleration_ned_mps2=acceleration_sp,
        )  # fmt: skip

    def _ramp(self, dt_s: float, speed_up: float) -> float:
        """PX4 ``TakeoffHandling::updateRamp``: the upward speed limit during the take-off,
        from −g / MPC_Z_VEL_P_ACC (a descent: no thrust) to ``speed_up``."""
        if self.ramp_progress >= 1.0:
            return speed_up
        ramp_s = self.params["MPC_TKO_RAMP_T"]
        self.ramp_progress = min(self.ramp_progress + dt_s / ramp_s, 1.0) if ramp_s > dt_s else 1.0
        start = -STANDARD_GRAVITY_MPS2 / max(self.params["MPC_Z_VEL_P_ACC"], 0.01)
        return start + self.ramp_progress * (speed_up - start)
