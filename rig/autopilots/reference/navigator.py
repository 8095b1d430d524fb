"""Flight modes and where each one wants the vehicle: PX4's navigator.

Modes are PX4's ``vehicle_status.nav_state`` values and travel in HEARTBEAT as PX4's custom
mode (``px4_custom_mode.h``: main mode in bits 16-23, sub mode in 24-31), so QGroundControl
and MAVSDK show their usual names. Each mode yields a :class:`Setpoint` for the position
controller; autonomous motion goes through PX4's jerk-limited trajectory
(:class:`~rig.autopilots.reference.trajectory.PositionSmoothing`), whose velocity and
acceleration the controller takes as feed-forward.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from rig.autopilots.reference.params import Parameters
from rig.autopilots.reference.trajectory import Limits, PositionSmoothing
from rig.mavlink.px4_api import mavlink

_NAN3 = np.full(3, np.nan)


class NavState(enum.IntEnum):
    """PX4 ``vehicle_status.nav_state`` (msg/VehicleStatus.msg)."""

    ALTCTL = 1
    POSCTL = 2
    AUTO_MISSION = 3
    AUTO_LOITER = 4
    DESCEND = 12
    TERMINATION = 13
    OFFBOARD = 14
    AUTO_TAKEOFF = 17
    AUTO_LAND = 18


class Px4MainMode(enum.IntEnum):
    """PX4 ``PX4_CUSTOM_MAIN_MODE`` (src/modules/commander/px4_custom_mode.h)."""

    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7


class Px4AutoMode(enum.IntEnum):
    """PX4 ``PX4_CUSTOM_SUB_MODE_AUTO``."""

    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6


#: nav_state → (main mode, sub mode) as PX4's ``get_px4_custom_mode`` reports it.
_CUSTOM_MODES = {
    NavState.ALTCTL: (Px4MainMode.ALTCTL, 0),
    NavState.POSCTL: (Px4MainMode.POSCTL, 0),
    NavState.AUTO_MISSION: (Px4MainMode.AUTO, Px4AutoMode.MISSION),
    NavState.AUTO_LOITER: (Px4MainMode.AUTO, Px4AutoMode.LOITER),
    NavState.DESCEND: (Px4MainMode.AUTO, Px4AutoMode.LAND),
    NavState.TERMINATION: (Px4MainMode.MANUAL, 0),
    NavState.OFFBOARD: (Px4MainMode.OFFBOARD, 0),
    NavState.AUTO_TAKEOFF: (Px4MainMode.AUTO, Px4AutoMode.TAKEOFF),
    NavState.AUTO_LAND: (Px4MainMode.AUTO, Px4AutoMode.LAND),
}
#: Modes a ground station may select (DESCEND and TERMINATION are failsafe-only).
_SELECTABLE: dict[tuple[int, int], NavState] = {  # (main mode, sub mode): a mode is its int
    _CUSTOM_MODES[s]: s
    for s in (NavState.ALTCTL, NavState.POSCTL, NavState.AUTO_MISSION, NavState.AUTO_LOITER,
              NavState.OFFBOARD, NavState.AUTO_TAKEOFF, NavState.AUTO_LAND)
}  # fmt: skip


def custom_mode(nav_state: NavState) -> int:
    """HEARTBEAT.custom_mode of a nav_state."""
    main, sub = _CUSTOM_MODES[nav_state]
    return (int(main) << 16) | (int(sub) << 24)


def nav_state_from_custom(main_mode: int, sub_mode: int) -> NavState | None:
    """The nav_state a DO_SET_MODE asks for, or None when this autopilot has no such mode
    (Manual, Stabilized, Acro)."""
    if main_mode in (Px4MainMode.ALTCTL, Px4MainMode.POSCTL, Px4MainMode.OFFBOARD):
        sub_mode = 0
    return _SELECTABLE.get((main_mode, sub_mode))


@dataclass(frozen=True)
class MissionItem:
    """One MISSION_ITEM_INT as uploaded (lat/lon in degE7, z in metres)."""

    seq: int
    frame: int
    command: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    autocontinue: int = 1


_GLOBAL_FRAMES = {
    mavlink.MAV_FRAME_GLOBAL: False,
    mavlink.MAV_FRAME_GLOBAL_INT: False,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: True,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: True,
}  # frame → altitude relative to home
_NAV_COMMANDS = {
    mavlink.MAV_CMD_NAV_WAYPOINT,
    mavlink.MAV_CMD_NAV_LOITER_TIME,
    mavlink.MAV_CMD_NAV_LAND,
    mavlink.MAV_CMD_NAV_TAKEOFF,
}
_DO_COMMANDS = {mavlink.MAV_CMD_DO_CHANGE_SPEED}


def check_mission_item(item: MissionItem) -> int:
    """MAV_MISSION_RESULT for an uploaded item: accepted, or why not."""
    if item.command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
        return mavlink.MAV_MISSION_ACCEPTED  # no position: home is the target, any frame
    if item.command in _NAV_COMMANDS:
        if item.frame not in _GLOBAL_FRAMES:
            return mavlink.MAV_MISSION_UNSUPPORTED_FRAME
        if not (
            -900_000_000 <= item.x <= 900_000_000 and -1_800_000_000 <= item.y <= 1_800_000_000
        ):
            return mavlink.MAV_MISSION_INVALID_PARAM5_X
        if not math.isfinite(item.z):
            return mavlink.MAV_MISSION_INVALID_PARAM7
        return mavlink.MAV_MISSION_ACCEPTED
    if item.command in _DO_COMMANDS:
        return mavlink.MAV_MISSION_ACCEPTED
    return mavlink.MAV_MISSION_UNSUPPORTED


@dataclass(frozen=True)
class Setpoint:
    """What the position controller should track; NaN entries are left uncontrolled."""

    position_ned_m: NDArray[np.float64]
    velocity_ned_mps: NDArray[np.float64]
    yaw_rad: float
    yawspeed_radps: float
    velocity_limits_mps: tuple[float, float, float]  # horizontal, up, down
    idle: bool = False  # on the ground, motors at idle, no control
    acceleration_ned_mps2: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))


class Navigator:
    """Set-points per mode, and the mission's progress.

    ``to_local`` maps (lat°, lon°, alt AMSL m) to the estimator's NED frame; ``home`` is the
    arming point (NED and AMSL altitude). Mission progress is reported through
    ``on_item_reached(seq)`` and ``on_current(seq)``.
    """

    def __init__(
        self,
        params: Parameters,
        to_local: Callable[[float, float, float], NDArray[np.float64]],
        on_item_reached: Callable[[int], None],
        on_current: Callable[[int], None],
    ) -> None:
        self.params = params
        self.to_local = to_local
        self.on_item_reached = on_item_reached
        self.on_current = on_current
        self.trajectory = PositionSmoothing()
        #: Where the vehicle is (the estimate), which the trajectory waits for.
        self.vehicle_ned = np.zeros(3)
        self.mission: list[MissionItem] = []
        self.mission_seq = 0
        self.home_ned = np.zeros(3)
        self.home_alt_amsl_m = 0.0
        self.takeoff_target_ned = np.zeros(3)
        self.hold_ned = np.zeros(3)
        self.yaw_sp_rad = 0.0
        self.offboard_position = _NAN3
        self.offboard_velocity = _NAN3
        self.offboard_yaw_rad = math.nan
        self.offboard_yawspeed_radps = math.nan
        self.cruise_speed_mps = math.nan
        self._hold_until_us: int | None = None
        self._mission_finished = False
        #: The landing's height set-point (NED down, m); None until a landing starts.
        self._land_down_m: float | None = None

    # --- mode entry -------------------------------------------------------------------
    def enter(
        self, position: NDArray[np.float64], velocity: NDArray[np.float64], yaw_rad: float
    ) -> None:
        """Start a mode from the current state: the trajectory begins where the vehicle is."""
        self.trajectory.reset(position, velocity)
        self.hold_ned = np.array(position, dtype=float)
        self.yaw_sp_rad = yaw_rad
        self._hold_until_us = None
        self._land_down_m = None

    def set_takeoff_target(self, position_ned: NDArray[np.float64], above_home_m: float) -> None:
        """Climb from ``position_ned`` to ``above_home_m`` over home (the local frame: it needs
        no global position)."""
        target = np.array(position_ned, dtype=float)
        target[2] = self.home_ned[2] - above_home_m
        self.takeoff_target_ned = target

    def set_mission(self, items: list[MissionItem]) -> None:
        self.mission = list(items)
        self.mission_seq = 0
        self._mission_finished = False
        self.cruise_speed_mps = math.nan

    def set_mission_current(self, seq: int) -> None:
        self.mission_seq = seq
        self._mission_finished = False
        self._hold_until_us = None

    @property
    def mission_finished(self) -> bool:
        return self._mission_finished

    # --- set-points -------------------------------------------------------------------
    def _auto_limits(self, climb_mps: float | None = None) -> Limits:
        """PX4 FlightTaskAuto's trajectory limits; ``climb_mps`` caps the climb (take-off)."""
        p = self.params
        cruise = self.cruise_speed_mps
        if not math.isfinite(cruise) or cruise <= 0.0:
            cruise = p["MPC_XY_CRUISE"]
        up = p["MPC_Z_V_AUTO_UP"] if climb_mps is None else min(p["MPC_Z_V_AUTO_UP"], climb_mps)
        return Limits(
            speed_xy=min(cruise, p["MPC_XY_VEL_MAX"]), speed_up=up, speed_down=p["MPC_Z_V_AUTO_DN"],
            accel_xy=p["MPC_ACC_HOR"], accel_up=p["MPC_ACC_UP_MAX"],
            accel_down=p["MPC_ACC_DOWN_MAX"], jerk=p["MPC_JERK_AUTO"],
            max_error_xy=p["MPC_XY_ERR_MAX"],
        )  # fmt: skip

    def _track(
        self, target: NDArray[np.float64], dt_s: float, limits: Limits | None = None
    ) -> Setpoint:
        self.trajectory.update(np.asarray(target, dtype=float), self.vehicle_ned, dt_s,
                               limits or self._auto_limits())  # fmt: skip
        speeds = (self.params["MPC_XY_VEL_MAX"], self.params["MPC_Z_VEL_MAX_UP"],
                  self.params["MPC_Z_VEL_MAX_DN"])  # fmt: skip
        return Setpoint(
            self.trajectory.position, self.trajectory.velocity, self.yaw_sp_rad, 0.0, speeds,
            acceleration_ned_mps2=self.trajectory.acceleration,
        )  # fmt: skip

    def _turn_towards(
        self, position: NDArray[np.float64], target: NDArray[np.float64], dt_s: float
    ) -> None:
        """Heading towards the target (PX4 MPC_YAW_MODE 0), at most MPC_YAWRAUTO_MAX."""
        offset = np.asarray(target) - np.asarray(position)
        if math.hypot(offset[0], offset[1]) < 2.0:
            return
        desired = math.atan2(offset[1], offset[0])
        error = (desired - self.yaw_sp_rad + math.pi) % (2 * math.pi) - math.pi
        step = math.radians(self.params["MPC_YAWRAUTO_MAX"]) * dt_s
        self.yaw_sp_rad += max(-step, min(step, error))

    def hold(self, dt_s: float) -> Setpoint:
        return self._track(self.hold_ned, dt_s)

    def takeoff(self, dt_s: float) -> Setpoint:
        limits = self._auto_limits(climb_mps=self.params["MPC_TKO_SPEED"])
        return self._track(self.takeoff_target_ned, dt_s, limits)

    def land(
        self, position: NDArray[np.float64], dt_s: float, dist_bottom_m: float | None = None
    ) -> Setpoint:
        """Hold the horizontal position and descend, slowing between MPC_LAND_ALT1/2 and,
        with a rangefinder's height above the ground, to MPC_LAND_CRWL below MPC_LAND_ALT3
        (PX4 ``FlightTaskAuto``: the heights are the rangefinder's when it has one, else
        above home).

        As in PX4 the height set-point moves down at the descent speed, and keeps moving
        once the vehicle stands on the ground: the growing height error takes the thrust
        down to the land detector's threshold within about a second of touchdown (with the
        speed alone it took the velocity integral 3-4 s)."""
        p = self.params
        height = self.home_ned[2] - position[2] if dist_bottom_m is None else dist_bottom_m
        alt1, alt2 = p["MPC_LAND_ALT1"], p["MPC_LAND_ALT2"]
        fast, slow = p["MPC_Z_V_AUTO_DN"], p["MPC_LAND_SPEED"]
        fraction = min(max((height - alt2) / max(alt1 - alt2, 1e-3), 0.0), 1.0)
        speed = slow + fraction * (fast - slow)
        if dist_bottom_m is not None and height < p["MPC_LAND_ALT3"]:
            speed = min(speed, p["MPC_LAND_CRWL"])
        self.trajectory.update(
            np.array([self.hold_ned[0], self.hold_ned[1], self.trajectory.position[2]]),
            self.vehicle_ned, dt_s, self._auto_limits(),
        )  # fmt: skip
        if self._land_down_m is None:
            self._land_down_m = float(position[2])
        self._land_down_m += speed * dt_s
        position_sp = np.array([*self.trajectory.position[:2], self._land_down_m])
        velocity_sp = np.array([self.trajectory.velocity[0], self.trajectory.velocity[1], speed])
        limits = (p["MPC_XY_VEL_MAX"], p["MPC_Z_VEL_MAX_UP"], max(speed, p["MPC_Z_VEL_MAX_DN"]))
        return Setpoint(position_sp, velocity_sp, self.yaw_sp_rad, 0.0, limits)

    def descend(self) -> Setpoint:
        """Failsafe without a position: level, no horizontal control, land speed down."""
        p = self.params
        velocity_sp = np.array([np.nan, np.nan, p["MPC_LAND_SPEED"]])
        limits = (p["MPC_XY_VEL_MAX"], p["MPC_Z_VEL_MAX_UP"], p["MPC_Z_VEL_MAX_DN"])
        return Setpoint(_NAN3, velocity_sp, self.yaw_sp_rad, 0.0, limits)

    def offboard(self) -> Setpoint:
        p = self.params
        yaw = self.offboard_yaw_rad if math.isfinite(self.offboard_yaw_rad) else self.yaw_sp_rad
        yawspeed = self.offboard_yawspeed_radps
        limits = (p["MPC_XY_VEL_MAX"], p["MPC_Z_VEL_MAX_UP"], p["MPC_Z_VEL_MAX_DN"])
        return Setpoint(
            self.offboard_position.copy(), self.offboard_velocity.copy(), yaw,
            yawspeed if math.isfinite(yawspeed) else 0.0, limits,
        )  # fmt: skip

    def mission_step(
        self, position: NDArray[np.float64], landed: bool, time_us: int, dt_s: float
    ) -> Setpoint | Literal["land"]:
        """Fly the current mission item; returns a set-point, or ``"land"`` when the item is a
        landing that has reached its descent, so the commander runs the land logic."""
        while self.mission_seq < len(self.mission):
            item = self.mission[self.mission_seq]
            if item.command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
                self.cruise_speed_mps = item.param2 if item.param2 > 0 else math.nan
                self._advance()
                continue
            break
        else:
            self._mission_finished = True
            return self.hold(dt_s)
        if item.command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            # Home at the current altitude, then land there (PX4 first climbs to
            # RTL_RETURN_ALT; the rig's missions fly low, so that climb is not emulated).
            target = np.array([self.home_ned[0], self.home_ned[1], position[2]])
        else:
            target = self._item_target(item, position)
        if item.command in (mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH):
            above = np.array([target[0], target[1], position[2]])
            if math.hypot(*(position[:2] - target[:2])) > self._acceptance_radius(item):
                self._turn_towards(position, above, dt_s)
                return self._track(above, dt_s)
            self.hold_ned = above
            return "land"
        if item.command == mavlink.MAV_CMD_NAV_TAKEOFF:
            target[:2] = self.hold_ned[:2]
        else:
            self._turn_towards(position, target, dt_s)
        setpoint = self._track(target, dt_s)
        if self._reached(item, position, target, time_us):
            self.hold_ned = target
            self._advance()
        return setpoint

    def land_item_done(self) -> None:
        """The landing of the current mission item touched down."""
        self._advance()

    def _item_target(self, item: MissionItem, position: NDArray[np.float64]) -> NDArray[np.float64]:
        relative = _GLOBAL_FRAMES[item.frame]
        alt = item.z + self.home_alt_amsl_m if relative else item.z
        if item.x == 0 and item.y == 0:  # no position: here, at the item's altitude
            target = np.array(self.hold_ned, dtype=float)
            target[2] = self.home_ned[2] - (alt - self.home_alt_amsl_m)
            return target
        return self.to_local(item.x * 1e-7, item.y * 1e-7, alt)

    def _acceptance_radius(self, item: MissionItem) -> float:
        if item.command == mavlink.MAV_CMD_NAV_WAYPOINT and item.param2 > 0.0:
            return item.param2
        return self.params["NAV_ACC_RAD"]

    def _reached(
        self,
        item: MissionItem,
        position: NDArray[np.float64],
        target: NDArray[np.float64],
        time_us: int,
    ) -> bool:
        if self._hold_until_us is None:
            horizontal = math.hypot(*(position[:2] - target[:2]))
            if item.command == mavlink.MAV_CMD_NAV_TAKEOFF:
                horizontal = 0.0
            vertical = abs(position[2] - target[2])
            if (
                horizontal > self._acceptance_radius(item)
                or vertical > self.params["NAV_MC_ALT_RAD"]
            ):
                return False
            hold_s = item.param1 if item.command in (
                mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LOITER_TIME) else 0.0  # fmt: skip
            self._hold_until_us = time_us + int(max(hold_s, 0.0) * 1e6)
        return time_us >= self._hold_until_us

    def _advance(self) -> None:
        self.on_item_reached(self.mission_seq)
        self._hold_until_us = None
        self.mission_seq += 1
        if self.mission_seq < len(self.mission):
            self.on_current(self.mission_seq)
