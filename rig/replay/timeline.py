"""What a replay reads from a real flight log: the state at its start, the pilot's timeline
(arm, modes, disarm), sticks, mission and home, and the set-point tracks of each drive."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray

from px4_logs import ARMING_STATE_ARMED, FlightLog
from quad_model.environment import GeoPoint
from quad_model.frames import geodetic_to_ned, ned_to_geodetic
from rig.mavlink.ground_link import PX4_MODES, MissionItem
from rig.mavlink.px4_api import mavlink
from rig.replay.options import Drive, ReplayError
from rig.scenarios.scenario import SetpointTrack

#: PX4's navigation states (vehicle_status.nav_state) a replay acts on.
NAV_STATE_MISSION, NAV_STATE_LOITER, NAV_STATE_OFFBOARD = 3, 4, 14


#: The mode the log armed in is selected this long before the arm (PX4 switches modes freely
#: while disarmed; the arm is then checked in that mode).
ARM_MODE_LEAD_S = 1.0


#: ``vehicle_status.latest_disarming_reason`` of a pilot's or ground station's disarm (stick
#: gesture, RC switch, external command: the same numbers in every PX4 since 1.13). Any other
#: disarm (landing, pre-flight timeout, failsafe) was PX4's own. Either way a PX4 replay sends
#: a disarm at the log's time, so the disarmed stretch after landing is the log's; PX4 takes
#: it only once it has landed, and otherwise disarms by itself later.
PILOT_DISARM_REASONS = frozenset({1, 2, 4})


#: nav_states flown on the pilot's sticks: PX4 needs manual control input in them.
STICK_MODES = frozenset({0, 1, 2, 10, 15})


#: Loiter commands (MAV_CMD_NAV_LOITER_UNLIM, _TIME, _TO_ALT): a navigator that started one
#: of these at the switch to Mission, then replaced it by the mission's first item, held
#: the vehicle where it was meanwhile (``ReplayLog.mission_start_holds``).
LOITER_COMMANDS = frozenset({17, 19, 31})


#: The navigator starts a mission item this soon after the switch to Mission (it runs at
#: 20 Hz); a later first record belongs to something else.
MISSION_START_S = 0.5


#: A mission item the real PX4 left within this long of making it current was passed where
#: the vehicle stood, not flown to: the X500's first waypoint, 0.8 m above the hovering
#: vehicle, was current for 50 ms in its v1.17. PX4 v1.14 SITL, given it as logged (on the
#: home at arming: 1.1 m below), descended to it first and ran the mission 1.9 s late;
#: given no such item, it climbed to the next one's height before leaving (its in-air
#: take-off step), 3.3 s late. Uploaded at the height it was passed, it is passed too.
#: No multicopter reaches a waypoint outside its acceptance radius this fast.
PASSED_AT_ONCE_S = 0.25


#: A home_position sample this far (m, any axis) from the one before is a home moved.
HOME_MOVED_M = 0.05


#: navigator_mission_item frames with a global position (MAV_FRAME GLOBAL*, PX4 stores 0).
GLOBAL_FRAMES = frozenset({0, 3, 5, 6})


#: Each drive's topic and fields, in SetpointTrack order (thrust is −thrust_body[2]).
#: What a mission item needs to go up (``Flight.flown_mission``).
_MISSION_ITEM_FIELDS = (
    "sequence_current", "frame", "latitude", "longitude", "altitude", "altitude_is_relative",
    "nav_cmd", "time_inside", "acceptance_radius", "loiter_radius", "yaw",
)  # fmt: skip


_DRIVE_FIELDS = {
    Drive.VELOCITY: ("vehicle_local_position_setpoint", ("vx", "vy", "vz", "yaw")),
    Drive.ATTITUDE: ("vehicle_attitude_setpoint",
                 ("q_d[0]", "q_d[1]", "q_d[2]", "q_d[3]", "thrust_body[2]")),
    Drive.RATES: ("vehicle_rates_setpoint", ("roll", "pitch", "yaw", "thrust_body[2]")),
}  # fmt: skip


class EventKind(StrEnum):
    """What happened in the real flight (:class:`FlightEvent`)."""

    ARM = "arm"
    DISARM = "disarm"
    #: The pilot's mode (``nav_state_user_intention``) changed.
    MODE = "mode"
    #: PX4 changed mode by itself (a failsafe).
    AUTOPILOT = "autopilot"


@dataclass(frozen=True)
class FlightEvent:
    """Something the pilot, a ground station or PX4 did in the real flight (log seconds):
    ``kind`` arm, disarm, mode (the pilot's mode, ``nav_state_user_intention``) or autopilot
    (PX4 changed mode by itself: a failsafe). ``commanded``: a PX4 replay sends it. A
    failsafe's mode (and the one it returns to) is commanded when a ground station can
    select it: the replay does not recreate the failsafe's cause (the X500's estimator lost
    its position for 2 s), and the pilot's sticks mean something else in another mode."""

    time_s: float
    kind: EventKind
    nav_state: int | None
    commanded: bool
    detail: str

    def describe(self) -> str:
        what = {EventKind.ARM: "armed", EventKind.DISARM: "disarmed"}.get(self.kind) or (
            f"mode {mode_name(self.nav_state)}"
            if self.kind is EventKind.MODE
            else f"PX4 switched to {mode_name(self.nav_state)} by itself"
        )
        action = "commanded" if self.commanded else "not commanded"
        return f"{self.time_s:.3f} s {what} ({self.detail}): {action}"


class ReplayLog(FlightLog):
    """What a replay reads from a flight log: the state at its start, the pilot's timeline,
    sticks and mission, home, and the set-point tracks of each drive."""

    def landed_at(self, time_s: float) -> bool:
        """On the ground at ``time_s``: the land detector's state, or without one as derived
        from the arming state and the height (:meth:`FlightLog.airborne_at`)."""
        return not bool(self.airborne_at(np.array([time_s]))[0])

    def height_at(self, time_s: float) -> float:
        """Height above the estimator's origin (where it booted, on the ground) at ``time_s``."""
        height = -self.value_at(
            "vehicle_local_position", "z", time_s, "the height at an airborne start"
        )
        if not math.isfinite(height) or height <= 0:
            raise ReplayError(
                f"{self.path}: vehicle_local_position.z = {-height:g} m at {time_s:g} s: no "
                "height to take off to for an airborne start"
            )
        return height

    def altitude_at(self, time_s: float) -> float | None:
        """The vehicle's altitude AMSL in force at ``time_s`` (None: not logged)."""
        return self.logged_at("vehicle_global_position", "alt", time_s)

    def home_altitude_at(self, time_s: float) -> float | None:
        """The real PX4's home altitude AMSL in force at ``time_s`` (None: not logged)."""
        return self.logged_at("home_position", "alt", time_s)

    def battery_voltage_v(self, time_s: float) -> float | None:
        """The pack's voltage at ``time_s`` (None: no battery_status). The replay starts
        landed and disarmed, where only the avionics load the pack: ≈ its open-circuit
        voltage (R·I is mV)."""
        if "battery_status" not in self.topics:
            return None
        return self.value_at("battery_status", "voltage_v", time_s, "the starting battery voltage")

    def heading_at(self, time_s: float) -> float:
        heading = self.value_at("vehicle_local_position", "heading", time_s, "the start heading")
        if not math.isfinite(heading):
            raise ReplayError(
                f"{self.path}: vehicle_local_position.heading is {heading} at "
                f"{time_s:g} s (the start heading)"
            )
        return heading

    def heading_resets(self, start_s: float, end_s: float) -> tuple[tuple[float, float], ...]:
        """(log s, rad): each jump the estimator made in its heading after ``start_s``.

        A reset is the estimator correcting itself (EKF2's in-flight magnetometer alignment
        once airborne, away from the ground's iron; a switch of estimator instance), not the
        vehicle turning: the X500's heading jumps 8.9° at 415.1 s, 2 s after take-off. Empty
        where the log predates ``heading_reset_counter``.
        """
        data = self.topics.get("vehicle_local_position", {})
        if "heading_reset_counter" not in data or "delta_heading" not in data:
            return ()
        time_s = data["timestamp"] / 1e6
        jumps = np.flatnonzero(np.diff(data["heading_reset_counter"]) != 0) + 1
        return tuple(
            (float(time_s[i]), float(data["delta_heading"][i]))
            for i in jumps
            if start_s < time_s[i] <= end_s and math.isfinite(data["delta_heading"][i])
        )

    def air_density(self, start_s: float, end_s: float) -> float | None:
        """Mean vehicle_air_data.rho over the replay (None: not logged or not plausible)."""
        data = self.topics.get("vehicle_air_data")
        if data is None or "rho" not in data:
            return None
        time_s = data["timestamp"] / 1e6
        rho = data["rho"][(time_s >= start_s) & (time_s <= end_s)]
        rho = rho[np.isfinite(rho) & (rho > 0.5) & (rho < 1.5)]  # air from sea level to 5 km
        return float(rho.mean()) if rho.size else None

    def peak_yaw_rate_deg_s(self, nav_state: int) -> float | None:
        """The largest |body z rate| (°/s, ``vehicle_angular_velocity``) while PX4 flew
        ``nav_state`` (``vehicle_status``); None without either topic or such a stretch."""
        status = self.topics.get("vehicle_status")
        rates = self.topics.get("vehicle_angular_velocity")
        if status is None or rates is None or "nav_state" not in status or "xyz[2]" not in rates:
            return None
        index = np.searchsorted(status["timestamp"], rates["timestamp"], "right") - 1
        flown = (index >= 0) & (status["nav_state"][np.clip(index, 0, None)] == nav_state)
        yaw_rate = np.abs(rates["xyz[2]"][flown].astype(float))
        yaw_rate = yaw_rate[np.isfinite(yaw_rate)]
        return float(np.degrees(yaw_rate.max())) if yaw_rate.size else None

    def auto_yaw_rates_deg_s(
        self, nav_states: frozenset[int], start_s: float, end_s: float
    ) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Per stretch flown in ``nav_states`` inside ``[start_s, end_s)``: the log
        seconds and |``trajectory_setpoint.yawspeed``| (°/s, NaN as 0: no yaw rate set),
        the first sample moved back to the mode switch; none without either topic."""
        status = self.topics.get("vehicle_status")
        setpoints = self.topics.get("trajectory_setpoint")
        if status is None or setpoints is None or "yawspeed" not in setpoints:
            return []
        nav = status["nav_state"]
        switched = np.maximum.accumulate(np.where(np.diff(nav, prepend=-1) != 0,
                                                  np.arange(len(nav)), 0))  # fmt: skip
        index = np.clip(np.searchsorted(status["timestamp"], setpoints["timestamp"], "right") - 1,
                        0, None)  # fmt: skip
        time_s = setpoints["timestamp"] / 1e6
        inside = np.isin(nav[index], list(nav_states)) & (time_s >= start_s) & (time_s < end_s)
        rates = np.nan_to_num(np.degrees(np.abs(setpoints["yawspeed"].astype(float))))
        edges = np.flatnonzero(np.diff(np.r_[0, inside.astype(int), 0]))
        stretches = []
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            times = time_s[a:b].copy()
            times[0] = max(status["timestamp"][switched[index[a]]] / 1e6, start_s)
            stretches.append((times, rates[a:b]))
        return stretches

    def hover_thrust(self) -> float | None:
        """Median of the valid hover_thrust_estimate.hover_thrust (None: none logged)."""
        data = self.topics.get("hover_thrust_estimate")
        if data is None or "hover_thrust" not in data:
            return None
        thrust = data["hover_thrust"][_valid(data)]
        thrust = thrust[np.isfinite(thrust) & (thrust > 0) & (thrust < 1)]
        return float(np.median(thrust)) if thrust.size else None

    def thrust_at_bottom_stick(self) -> float | None:
        """Median collective thrust set-point while the throttle stick sat at its bottom
        (within 1 %), None without such samples or either topic."""
        sticks = self.topics.get("manual_control_setpoint")
        thrust = self.topics.get("vehicle_thrust_setpoint")
        if sticks is None or thrust is None or "throttle" not in sticks or "xyz[2]" not in thrust:
            return None
        index = np.searchsorted(sticks["timestamp"], thrust["timestamp"], "right") - 1
        held = sticks["throttle"][np.clip(index, 0, None)]
        bottom = (index >= 0) & (held <= -0.99)
        return float(np.median(-thrust["xyz[2]"][bottom])) if bottom.any() else None

    def home(self) -> GeoPoint | None:
        """The first valid home position (the flying site), None without one."""
        data = self.topics.get("home_position")
        if data is None or not len(data["timestamp"]):
            return None
        lat, lon, alt = (float(data[k][0]) for k in ("lat", "lon", "alt"))
        if not (math.isfinite(lat + lon + alt) and -90 <= lat <= 90 and -180 <= lon <= 180):
            return None
        return GeoPoint(lat, lon, alt)

    def home_moves(
        self, home: GeoPoint | None, armed_s: float | None, disarmed_s: float
    ) -> tuple[tuple[float, GeoPoint], ...]:
        """Where and when the real PX4 moved its home while armed (``armed_s`` to
        ``disarmed_s``, log seconds): PX4 sets it again at take-off, on its estimate then
        (the X500's EKF2 had just put its height 1.7 m up: home 1.82 m above the one it
        armed at), and Land and Return descend, slow down and land by the height above it.
        Moves of less than :data:`HOME_MOVED_M` are left out."""
        data = self.topics.get("home_position")
        if home is None or armed_s is None or data is None:
            return ()
        moves: list[tuple[float, GeoPoint]] = []
        previous = home
        for k in range(1, len(data["timestamp"])):
            time_s = float(data["timestamp"][k]) / 1e6
            point = GeoPoint(*(float(data[f][k]) for f in ("lat", "lon", "alt")))
            if not (armed_s < time_s < disarmed_s and math.isfinite(point.alt_amsl_m)):
                continue
            north, east, down = geodetic_to_ned(point.lat_deg, point.lon_deg, point.alt_amsl_m,
                                                previous.lat_deg, previous.lon_deg,
                                                previous.alt_amsl_m)  # fmt: skip
            if max(abs(north), abs(east), abs(down)) >= HOME_MOVED_M:
                moves.append((time_s, point))
                previous = point
        return tuple(moves)

    def arming(self, start_s: float, end_s: float) -> tuple[float | None, float | None]:
        """The real arm and disarm times clipped to ``[start_s, end_s)`` (None: not in it).

        The arm time is ``vehicle_status.armed_time`` of the first armed sample: the logger
        starts on arming, so the first sample comes after it.
        """
        status = self.topic("vehicle_status", "arming times", ("arming_state",))
        times_s = status["timestamp"] / 1e6
        armed = status["arming_state"] == ARMING_STATE_ARMED
        if not armed.any():
            return None, None
        first = int(np.argmax(armed))
        armed_at_s = _arm_time_s(status, first)
        disarmed_after = np.nonzero(~armed[first:])[0]
        disarm_s = float(times_s[first + disarmed_after[0]]) if len(disarmed_after) else None
        arm_s = max(armed_at_s, start_s) if armed_at_s < end_s else None
        if disarm_s is not None and not start_s < disarm_s < end_s:
            disarm_s = None
        return arm_s, disarm_s

    def timeline(self, start_s: float, end_s: float) -> tuple[FlightEvent, ...]:
        """The flight's arm, disarm and mode switches in ``[start_s, end_s)``, and what PX4
        did by itself, from ``vehicle_status``; the mode in force at ``start_s`` comes first.

        The pilot's mode is ``nav_state_user_intention`` (``nav_state`` in a PX4 before
        1.14): a replay commands it while armed (and the mode armed in), never a mode PX4
        chose itself in a failsafe, nor the mode it returns to after an automatic disarm.
        """
        status = self.topic(
            "vehicle_status", "the flight's arm, disarm and mode switches",
            ("nav_state", "arming_state"),
        )  # fmt: skip
        times_s = status["timestamp"] / 1e6
        nav = status["nav_state"].astype(int)
        intended = status.get("nav_state_user_intention", status["nav_state"]).astype(int)
        armed = status["arming_state"] == ARMING_STATE_ARMED
        reasons = status.get("latest_disarming_reason")
        failsafe = status.get("failsafe", np.zeros(len(nav)))
        events: list[FlightEvent] = []
        flown = False
        for k in range(len(times_s)):
            time_s, mode = float(times_s[k]), int(intended[k])
            if armed[k] != (armed[k - 1] if k else False):
                events.append(self._arming_event(status, k, armed[k], reasons))
                time_s = events[-1].time_s  # the mode it armed in, or left to after a disarm
            flown = flown or bool(armed[k])
            if not k or mode != intended[k - 1]:
                if mode not in PX4_MODES:
                    commanded, detail = False, "not a mode a ground station selects"
                elif armed[k] or not flown:
                    commanded, detail = True, "the pilot's"
                else:
                    commanded, detail = False, "after the disarm: PX4's own"
                events.append(FlightEvent(time_s, EventKind.MODE, mode, commanded, detail))
            elif nav[k] != nav[k - 1]:
                cause = "failsafe" if failsafe[k] else "back from a failsafe"
                flown_mode = int(nav[k]) in PX4_MODES and bool(armed[k])
                detail = (f"{cause}: commanded, so the sticks act in the mode the vehicle flew"
                          if flown_mode else f"{cause}: PX4 decides again")  # fmt: skip
                events.append(FlightEvent(float(times_s[k]), EventKind.AUTOPILOT, int(nav[k]),
                                          flown_mode, detail))  # fmt: skip
        return _clipped(events, start_s, end_s)

    def _arming_event(
        self, status: dict[str, NDArray[Any]], k: int, armed: bool, reasons: NDArray[Any] | None
    ) -> FlightEvent:
        if armed:  # the logger starts on arming: the arm comes before the first sample
            return FlightEvent(_arm_time_s(status, k), EventKind.ARM, None, True, "the pilot's")
        reason = None if reasons is None else int(reasons[k])
        whose = ("the pilot's" if reason is None or reason in PILOT_DISARM_REASONS else
                 f"PX4's own, reason {reason}")  # fmt: skip
        detail = f"{whose}; refused unless PX4 has landed"
        return FlightEvent(float(status["timestamp"][k]) / 1e6, EventKind.DISARM, None, True,
                           detail)  # fmt: skip

    def sticks(self, start_s: float, end_s: float) -> SetpointTrack | None:
        """The pilot's sticks (``manual_control_setpoint`` roll, pitch, yaw, throttle, PX4's
        −1..1) in run seconds from ``start_s``, first the ones in force then; None without."""
        data = self.topics.get("manual_control_setpoint")
        fields = ("roll", "pitch", "yaw", "throttle")
        if data is None or any(f not in data for f in fields):
            return None
        valid = _valid(data)
        if not valid.any():
            return None
        times_s = data["timestamp"][valid] / 1e6
        values = _hold_last_finite(np.column_stack([data[f][valid].astype(float) for f in fields]))
        inside = (times_s > start_s) & (times_s < end_s)
        before = np.nonzero(times_s <= start_s)[0]
        first = values[before[-1]] if len(before) else values[0]
        return SetpointTrack(
            "manual",
            (0.0, *(float(t) - start_s for t in times_s[inside])),
            tuple(tuple(float(v) for v in row) for row in (first, *values[inside])),
        )

    def flown_mission(
        self, home: GeoPoint | None, home_replayed: bool = False
    ) -> tuple[tuple[MissionItem, ...], tuple[str, ...]]:
        """The mission as PX4 flew it, uploadable as MISSION_ITEM_INT, and what the log
        could not say about it. ``navigator_mission_item`` holds for each sequence number
        the last item logged with it (one the navigator inserted, such as a climb before the
        first waypoint, is logged before it); positions and heights are put where the real
        vehicle flew them (:func:`_mission_positions`, :meth:`_mission_altitudes`)."""
        data = self.topics.get("navigator_mission_item")
        if data is None or not len(data["timestamp"]):
            return (), ("the log flew Mission mode but holds no navigator_mission_item: no "
                        "mission to upload",)  # fmt: skip
        missing = [field for field in _MISSION_ITEM_FIELDS if field not in data]
        if missing:
            return (), (f"navigator_mission_item has no field {missing[0]}: no mission to "
                        "upload",)  # fmt: skip
        last = _last_row_per_item(data)
        flown = 0
        while flown in last:
            flown += 1
        notes = []
        if flown < len(last):
            notes.append(
                f"mission items {sorted(set(last) - set(range(flown)))} follow a gap "
                f"(item {flown} never became current): only items 0-{flown - 1} go up"
            )
        results = self.topics.get("mission_result")
        total = (
            int(results["seq_total"].max())
            if results is not None and "seq_total" in results
            else flown
        )
        if total > flown:
            notes.append(
                f"the log's mission had {total} items; {flown} became current and "
                f"could be uploaded (the log holds no more)"
            )
        rows = [last[seq] for seq in range(flown)]
        frames = {int(data["frame"][k]) for k in rows}
        if not frames <= GLOBAL_FRAMES:
            return (), (
                *notes,
                f"mission frame(s) {sorted(frames - GLOBAL_FRAMES)} are not "
                "global positions: no mission to upload",
            )
        positions, position_notes = _mission_positions(data, rows, home)
        altitudes, altitude_notes = self._mission_altitudes(data, rows, home, home_replayed)
        notes += [*position_notes, *altitude_notes]
        items = tuple(
            MissionItem(
                frame=(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT if data["altitude_is_relative"][k]
                       else mavlink.MAV_FRAME_GLOBAL_INT),
                command=int(data["nav_cmd"][k]),
                lat_deg=lat, lon_deg=lon, alt_m=altitude,
                param1=float(data["time_inside"][k]), param2=float(data["acceptance_radius"][k]),
                param3=float(data["loiter_radius"][k]), param4=math.degrees(float(data["yaw"][k])),
            )
            for k, (lat, lon), altitude in zip(rows, positions, altitudes, strict=True)
        )  # fmt: skip
        return items, tuple(notes)

    def mission_start_holds(self, events: Sequence[FlightEvent]) -> tuple[tuple[float, float], ...]:
        """Per commanded switch to Mission, the time the real navigator held the vehicle
        before the mission's first item: (switch, hold) in log seconds, where it first
        started a loiter it then replaced by the item logged last with the same sequence
        number (the one the replay uploads, :meth:`flown_mission`).

        Why: PX4 v1.17 (the X500's) loiters at the vehicle's position for 0.41 s after the
        switch, then starts the mission; PX4 v1.14 SITL starts it at once, and ran the
        whole mission and the POSCTL flying after it 0.4 s ahead of the log.
        """
        data = self.topics.get("navigator_mission_item")
        if data is None or not {"sequence_current", "nav_cmd"} <= data.keys():
            return ()
        times_s = data["timestamp"] / 1e6
        sequence = data["sequence_current"].astype(int)
        last = _last_row_per_item(data)
        holds = []
        for event in events:
            if not (event.commanded and event.nav_state == NAV_STATE_MISSION):
                continue
            first = int(np.searchsorted(times_s, event.time_s))
            if first == len(times_s) or times_s[first] > event.time_s + MISSION_START_S:
                continue
            flown = last[int(sequence[first])]
            if (
                flown > first
                and int(data["nav_cmd"][first]) in LOITER_COMMANDS
                and (sequence[first:flown] == sequence[first]).all()
            ):
                holds.append((event.time_s, float(times_s[flown] - times_s[first])))
        return tuple(holds)

    def _mission_altitudes(
        self,
        data: dict[str, NDArray[Any]],
        rows: list[int],
        home: GeoPoint | None,
        home_replayed: bool,
    ) -> tuple[list[float], list[str]]:
        """Each item's altitude for this replay. A relative one is above the home the real
        PX4 held when it flew the item (PX4 sets home again at take-off, on its estimate
        then): as logged where the replay moves its home as the real one did
        (``home_replayed``), else moved onto this replay's home, the log's first. One passed
        at once (:data:`PASSED_AT_ONCE_S`) is put where the vehicle passed it."""
        times_s = data["timestamp"] / 1e6
        sequence = data["sequence_current"].astype(int)
        altitudes = [float(data["altitude"][k]) for k in rows]
        notes: list[str] = []
        if home is None:
            return altitudes, notes
        relative = [bool(data["altitude_is_relative"][k]) for k in rows]
        held = {k: self.home_altitude_at(times_s[k]) for k in rows}
        homes_then = {k: home.alt_amsl_m if h is None else h for k, h in held.items()}
        references = homes_then if home_replayed else dict.fromkeys(rows, home.alt_amsl_m)
        moves_m = {
            k: homes_then[k] - references[k]
            for k, is_relative in zip(rows, relative, strict=True)
            if is_relative
        }
        moved = sorted({round(m, 2) for m in moves_m.values() if abs(m) >= 0.01})
        if moved:
            notes.append(
                f"relative mission altitudes moved by {', '.join(f'{m:+g}' for m in moved)} m: "
                f"the real PX4 flew them above a home it set again at take-off, not the log's "
                f"first ({home.alt_amsl_m:.2f} m), this replay's"
            )
        for index, k in enumerate(rows):
            altitudes[index] += moves_m.get(k, 0.0)
            following = k + 1 + np.nonzero(sequence[k + 1 :] > sequence[k])[0]
            if index == len(rows) - 1 or not len(following):
                continue
            current_s = float(times_s[following[0]] - times_s[k])
            standing = self.altitude_at(float(times_s[k]))
            if current_s >= PASSED_AT_ONCE_S or standing is None:
                continue
            passed_at = standing - (references[k] if relative[index] else 0.0)
            notes.append(
                f"mission item {sequence[k]} was current for {current_s:.2f} s: the real PX4 "
                f"passed it where the vehicle stood, {passed_at:.1f} m against its "
                f"{altitudes[index]:.1f} m; uploaded at that height, so this PX4 passes it "
                "too instead of flying to it first"
            )
            altitudes[index] = passed_at
        return altitudes, notes

    def track(self, drive: Drive, start_s: float, end_s: float) -> SetpointTrack:
        """The drive's setpoints in run seconds from ``start_s``, first the one in force then.

        NaN components hold the last finite value: PX4 logs NaN for an axis its mode does
        not control (vx, vy, vz before take-off, thrust in some modes), and the replay must
        still command something there; before any finite value a velocity is 0 (the vehicle
        is landed at the start) and a rate or thrust is 0. Yaw stays NaN (not controlled).
        Set-points logged before an estimator heading reset are turned by the resets after
        them, into the frame the replay starts in (:meth:`heading_resets`).
        """
        name, fields = _DRIVE_FIELDS[drive]
        data = self.topic(name, f"needed by --drive {drive}", fields)
        times_s = data["timestamp"] / 1e6
        values = np.column_stack([data[f].astype(float) for f in fields])
        resets = self.heading_resets(start_s, end_s)
        turn = np.zeros_like(times_s)
        for reset_s, delta in resets:
            turn[times_s < reset_s] += delta
        if drive is Drive.VELOCITY:
            cos, sin = np.cos(turn), np.sin(turn)
            values[:, 0], values[:, 1] = (
                cos * values[:, 0] - sin * values[:, 1],
                sin * values[:, 0] + cos * values[:, 1],
            )
            values[:, 3] = np.remainder(values[:, 3] + turn + np.pi, 2 * np.pi) - np.pi
        elif drive is Drive.ATTITUDE:  # q_d ← (a turn about NED down) ⊗ q_d, for every sample
            # at once (quad_model.frames.quat_multiply takes one pair)
            w, x, y, z = values[:, :4].T
            c, s = np.cos(turn / 2), np.sin(turn / 2)
            values[:, :4] = np.column_stack(
                (c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w)
            )
        if drive is not Drive.VELOCITY:
            values[:, -1] = -values[:, -1]  # thrust = −thrust_body[2] (PX4 FRD, 0..1)
        held = values.shape[1] - 1 if drive is Drive.VELOCITY else values.shape[1]
        values[:, :held] = _hold_last_finite(values[:, :held])
        inside = (times_s > start_s) & (times_s < end_s)
        before = np.nonzero(times_s <= start_s)[0]
        first = values[before[-1]] if len(before) else _initial(drive, values[0])
        track_times = (0.0, *(float(t) - start_s for t in times_s[inside]))
        rows = (first, *values[inside])
        return SetpointTrack(drive, track_times, tuple(tuple(float(v) for v in r) for r in rows))


def _last_row_per_item(data: Mapping[str, NDArray[Any]]) -> dict[int, int]:
    """navigator_mission_item's last row for each sequence number: the item as flown (one
    the navigator started first in its place, a climb or a loiter, is logged before it)."""
    return {int(seq): k for k, seq in enumerate(data["sequence_current"])}


def _mission_positions(
    data: dict[str, NDArray[Any]], rows: list[int], home: GeoPoint | None
) -> tuple[list[tuple[float, float]], list[str]]:
    """Each mission item's latitude and longitude for this replay. A log whose positions
    were moved by whole degrees to hide the site (its home, not its mission) has each item
    put at its distance and bearing from the home moved back: a shift in degrees would
    scale the east-west legs by the ratio of the two latitudes' cosines."""
    lat = np.array([float(data["latitude"][k]) for k in rows])
    lon = np.array([float(data["longitude"][k]) for k in rows])
    positions = [(float(a), float(o)) for a, o in zip(lat, lon, strict=True)]
    if home is None:
        return positions, []
    shift = tuple(
        float(np.round(h - np.median(v))) for h, v in ((home.lat_deg, lat), (home.lon_deg, lon))
    )
    if shift == (0.0, 0.0):
        return positions, []
    site_lat, site_lon = home.lat_deg - shift[0], home.lon_deg - shift[1]
    moved = []
    for item_lat, item_lon in positions:
        north, east, _ = geodetic_to_ned(item_lat, item_lon, 0.0, site_lat, site_lon, 0.0)
        moved.append(ned_to_geodetic((north, east, 0.0), home.lat_deg, home.lon_deg, 0.0)[:2])
    scale = math.cos(math.radians(home.lat_deg)) / math.cos(math.radians(site_lat))
    note = (
        f"the mission items lie {shift[0]:g}° N, {shift[1]:g}° E from the log's home: whole "
        "degrees, the uploader's offset of the log's positions, taken out; each item keeps "
        f"its distance and bearing from home (moved in degrees, the east-west legs would "
        f"scale by {scale:.2f})"
    )
    return moved, [note]


def _clipped(events: list[FlightEvent], start_s: float, end_s: float) -> tuple[FlightEvent, ...]:
    """The events in ``[start_s, end_s)``; the pilot's mode in force at ``start_s`` (if the
    flight was armed then) comes first, moved to ``start_s``, and the arm with it when it
    came before ``start_s`` (the logger starts on arming: the 8S quad's arm is 5 ms before
    its log's start)."""
    before = [e for e in events if e.time_s < start_s]
    inside = [e for e in events if start_s <= e.time_s < end_s]
    modes = [e for e in before if e.kind is EventKind.MODE]
    armed = [e for e in before if e.kind in (EventKind.ARM, EventKind.DISARM)]
    if modes and armed and armed[-1].kind is EventKind.ARM:
        inside[:0] = [
            replace(modes[-1], time_s=start_s, commanded=True, detail="in force at --start"),
            replace(armed[-1], time_s=start_s, detail=f"{armed[-1].detail}, before --start"),
        ]
    return tuple(inside)


def mode_name(nav_state: int | None) -> str:
    mode = PX4_MODES.get(nav_state) if nav_state is not None else None
    return mode[2] if mode is not None else f"nav_state {nav_state}"


def delayed(track: SetpointTrack, delay_s: float) -> SetpointTrack:
    """The track ``delay_s`` later (after an airborne start's lead-in)."""
    if not delay_s:
        return track
    return SetpointTrack(track.kind, tuple(t + delay_s for t in track.times_s), track.values)


def _initial(drive: Drive, first: NDArray[np.float64]) -> NDArray[np.float64]:
    """The setpoint before the topic's first sample: at rest on the ground."""
    if drive is Drive.VELOCITY:
        return np.array([0.0, 0.0, 0.0, first[3]])
    if drive is Drive.ATTITUDE:
        return np.array([*first[:4], 0.0])
    return np.zeros(4)


def _valid(data: dict[str, NDArray[Any]]) -> NDArray[np.bool_]:
    """A topic's ``valid`` flags (every sample valid in a topic without them)."""
    if "valid" in data:
        return data["valid"].astype(bool)
    return np.ones(len(data["timestamp"]), bool)


def _arm_time_s(status: dict[str, NDArray[Any]], k: int) -> float:
    """When the vehicle armed, for armed sample ``k``: ``armed_time`` (the logger starts on
    arming, so the first armed sample comes after it), or the sample's time in a log
    without it (or with 0 there)."""
    armed_us = float(status["armed_time"][k]) if "armed_time" in status else 0.0
    return (armed_us or float(status["timestamp"][k])) / 1e6


def _hold_last_finite(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Replace each NaN by the last finite value above it in its column (0 before any)."""
    held = values.copy()
    last = np.zeros(values.shape[1])
    for row in held:
        finite = np.isfinite(row)
        last[finite] = row[finite]
        row[~finite] = last[~finite]
    return held
