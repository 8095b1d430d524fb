"""A PX4 flight log read once per command: its topics, parameters, firmware and time span,
a topic's value at a time, and the spans every tool of a flight needs (armed, airborne,
steady hover).

Why one reader: identification, the wind estimate, the vibration fit and a replay all ask
the same log the same questions; each parsing it again cost seconds and gave each its own
error wording. ``topics`` are the first instance (``multi_id`` 0) of each topic and
:meth:`FlightLog.instances` every instance (the motors may be on the second
``actuator_outputs``), each row-sorted by its time; a topic a newer PX4 has and an older log
lacks is derived from what the log holds (:mod:`px4_logs.layouts`) and the note says how, as
is the airborne span of a log without the land detector.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple, Self

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter1d

from px4_logs.errors import LogError
from px4_logs.layouts import LogParts, derive_missing
from px4_logs.outputs import MOTOR_FUNCTIONS
from px4_logs.ulog import firmware_name, read_ulog

#: Steady hover: airborne, RMS over HOVER_SMOOTH_S of |v| and of each body rate below these,
#: for at least MIN_HOVER_S (a position-hold hover with a pilot's small corrections qualifies).
HOVER_SMOOTH_S = 1.0
HOVER_MAX_SPEED_MPS = 0.6
HOVER_MAX_RATE_RADPS = 0.25
MIN_HOVER_S = 3.0
#: … and the thrust set-point within this fraction of its airborne median.
HOVER_THRUST_BAND = 0.2
#: Without a land detector: airborne while armed and more than AIRBORNE_HEIGHT_M above the
#: height of the first ARMED_GROUND_S armed (on the ground, spinning up: a baro's noise is
#: ±0.2 m, a climb-out passes 0.5 m within a second), or without a height while the thrust
#: set-point is above AIRBORNE_THRUST_FRACTION of its hover level (its median while armed
#: above half its armed maximum: a pilot's spin-up and idle stay below it).
AIRBORNE_HEIGHT_M = 0.5
ARMED_GROUND_S = 1.0
AIRBORNE_THRUST_FRACTION = 0.8
#: vehicle_status.arming_state of an armed vehicle (PX4's msg/VehicleStatus.msg).
ARMING_STATE_ARMED = 2

Topic = Mapping[str, NDArray[Any]]


class _Airborne(NamedTuple):
    time_s: NDArray[np.float64]
    airborne: NDArray[np.bool_]
    #: How it was derived where the log has no land detector, else "".
    note: str


class FlightLog:
    """The parts of a PX4 ULog the rig's tools read, with one-line errors naming file and field."""

    def __init__(
        self,
        path: str | Path,
        topics: Mapping[str, Topic | Sequence[Topic]],
        parameters: Mapping[str, float],
        *,
        firmware: str = "",
        warnings: tuple[str, ...] = (),
        first_s: float | None = None,
        last_s: float | None = None,
    ) -> None:
        """A log from its topics (field → array, each with its ``timestamp`` in µs; a
        sequence of them in ``multi_id`` order for a topic logged in several instances):
        :meth:`read` parses a file; a test or a tool can build one in memory."""
        self.path = Path(path)
        self.parameters = dict(parameters)
        self.firmware = firmware
        self.warnings = warnings  # pyulog's, become a run's notes
        grouped = {
            name: (data,) if isinstance(data, Mapping) else tuple(data)
            for name, data in topics.items()
        }
        if not grouped:
            raise LogError(f"{self.path}: the ULog holds no logged data")
        stamps = [np.asarray(d["timestamp"], float) for group in grouped.values() for d in group]
        self.first_s = min(float(t[0]) for t in stamps) / 1e6 if first_s is None else first_s
        self.last_s = max(float(t[-1]) for t in stamps) / 1e6 if last_s is None else last_s
        instances = {
            name: tuple(_by_time(name, d) for d in group) for name, group in grouped.items()
        }
        own = {name: group[0] for name, group in instances.items()}  # derive_missing adds to it
        #: Notes of what was derived: topics of an older PX4's layout, the airborne span.
        self.derived = derive_missing(LogParts(own, instances, self.parameters, self.path))
        self.topics: dict[str, dict[str, NDArray[Any]]] = own
        self._instances = {name: (own[name], *instances.get(name, ())[1:]) for name in own}
        self._time_s = {name: _stamp(name, data) * 1e-6 for name, data in own.items()}
        self._airborne = self._airborne_samples()
        if isinstance(self._airborne, _Airborne) and self._airborne.note:
            self.derived = (*self.derived, self._airborne.note)

    @classmethod
    def read(cls, path: str | Path) -> Self:
        """Parse a ULog file, every instance of each topic."""
        path = Path(path)
        if not path.is_file():
            raise LogError(f"{path}: flight log not found")
        ulog, warnings = read_ulog(path)
        # A topic's first sample may be its last one before the logger started (published
        # at boot: the 8S quad's actuator_outputs at 0.6 s, logging from 104.9 s); the
        # header's start time bounds the logged span (0 in some logs, the X500's).
        first_us = min((float(d.data["timestamp"][0]) for d in ulog.data_list), default=0.0)
        last_us = max((float(d.data["timestamp"][-1]) for d in ulog.data_list), default=0.0)
        topics: dict[str, list[dict[str, NDArray[Any]]]] = {}
        for data in sorted(ulog.data_list, key=lambda d: d.multi_id):
            topics.setdefault(data.name, []).append(data.data)
        return cls(
            path,
            topics,
            ulog.initial_parameters,
            firmware=firmware_name(ulog.msg_info_dict),
            warnings=warnings,
            first_s=max(first_us, float(ulog.start_timestamp)) / 1e6,
            last_s=last_us / 1e6,
        )

    def topic(self, name: str, why: str, fields: tuple[str, ...] = ()) -> dict[str, NDArray[Any]]:
        """Topic ``name`` holding ``fields``; a log without them is one line saying ``why``
        they were needed (a damaged or older log)."""
        if name not in self.topics:
            raise LogError(f"{self.path}: topic {name} ({why}) is not in the log")
        data = self.topics[name]
        missing = [field for field in fields if field not in data]
        if missing:
            raise LogError(f"{self.path}: topic {name} has no field {missing[0]} ({why})")
        return data

    def instances(self, name: str) -> tuple[dict[str, NDArray[Any]], ...]:
        """Every instance of topic ``name`` in ``multi_id`` order, each sorted by time (the
        first is ``topics[name]``); none when the log lacks it."""
        return self._instances.get(name, ())

    def time_s(self, name: str) -> NDArray[np.float64]:
        """Seconds of each row of topic ``name`` (its sample time where PX4 logs one)."""
        return self._time_s[name]

    def series(self, name: str, field: str, why: str) -> tuple[NDArray[np.float64], NDArray[Any]]:
        """(time s, values) of one field, repeated stamps dropped."""
        data = self.topic(name, why, (field,))
        time_s, values = self._time_s[name], data[field].astype(float)
        keep = np.concatenate(([True], np.diff(time_s) > 0))
        return time_s[keep], values[keep]

    def value_at(self, name: str, field: str, time_s: float, why: str) -> float:
        """The field's value in force at ``time_s`` (the first sample's before the topic starts)."""
        data = self.topic(name, why, (field,))
        index = max(int(np.searchsorted(self._time_s[name], time_s, "right")) - 1, 0)
        return float(data[field][index])

    def logged_at(self, name: str, field: str, time_s: float) -> float | None:
        """:meth:`value_at` for what a tool can do without: None when the topic, the field
        or a finite value is missing."""
        if field not in self.topics.get(name, {}):
            return None
        value = self.value_at(name, field, time_s, "")
        return value if math.isfinite(value) else None

    def airborne_span(self) -> tuple[float, float]:
        """First to last sample the land detector called airborne (without one, as
        :meth:`_airborne_samples` derives it)."""
        time_s, airborne = self._airborne_or_raise()
        flying = time_s[airborne]
        if flying.size == 0:
            raise LogError(f"{self.path}: the vehicle never left the ground")
        return float(flying[0]), float(flying[-1])

    def airborne_at(self, time_s: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether the vehicle was airborne at each of ``time_s``: the land detector's state
        in force then, or without one as derived (``derived`` says how)."""
        return _step_at(*self._airborne_or_raise(), np.asarray(time_s, dtype=float))

    def rotor_speeds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """The rotor speeds the ESCs measured: (time s, rad/s per sample × motor 1..N) from
        ``esc_status.esc[i].esc_rpm``; None when no instance reports a speed. Motor m is the
        ESC whose ``actuator_function`` is Motor m (PX4 1.14 on), else ESC m − 1 (a driver
        reports its ESCs in its output order); N is ``CA_ROTOR_COUNT``, else the ESCs."""
        for data in self.instances("esc_status"):
            rpm_by_motor = {}
            reporting = [int(f[4 : f.index("]")]) for f in data if f.endswith("].esc_rpm")]
            for esc in reporting:
                rpm = data[f"esc[{esc}].esc_rpm"]
                function = data.get(f"esc[{esc}].actuator_function")
                last = int(np.max(function)) if function is not None else 0
                motor = last - 100 if last in MOTOR_FUNCTIONS else esc + 1
                rpm_by_motor[motor] = np.abs(np.asarray(rpm, dtype=float))
            count = int(self.parameters.get("CA_ROTOR_COUNT", 0)) or len(rpm_by_motor)
            motors = range(1, count + 1)
            if count and all(m in rpm_by_motor for m in motors):
                speeds = np.column_stack([rpm_by_motor[m] for m in motors]) * (2.0 * math.pi / 60.0)
                if np.any(speeds > 0):  # ESCs without telemetry log zeros
                    return _stamp("esc_status", data) * 1e-6, speeds
        return None

    def armed_span(self) -> tuple[float, float, bool]:
        """First arm to the disarm after the last armed sample (``actuator_armed``), else the
        airborne span; and whether the span ends at a logged disarm."""
        if "actuator_armed" in self.topics:
            time_s, armed = self.series("actuator_armed", "armed", "")
            if np.any(armed > 0.5):
                on = time_s[armed > 0.5]
                off = time_s[(time_s > on[-1]) & (armed < 0.5)]
                if off.size:
                    return float(on[0]), float(off[0]), True
                return float(on[0]), float(time_s[-1]), False
        return (*self.airborne_span(), False)

    def hover_windows(self) -> tuple[tuple[float, float], ...]:
        """Steady-hover spans: airborne, RMS |v| ≤ HOVER_MAX_SPEED_MPS (vz alone where PX4
        flags vx, vy invalid), RMS of every body rate ≤ HOVER_MAX_RATE_RADPS (over
        HOVER_SMOOTH_S) and the thrust within HOVER_THRUST_BAND of its airborne median, for
        at least MIN_HOVER_S."""
        why = "velocity for hover detection"
        time_s, vz = self.series("vehicle_local_position", "vz", why)
        horizontal_sq = sum(self.series("vehicle_local_position", f, why)[1] ** 2
                            for f in ("vx", "vy"))  # fmt: skip
        if "v_xy_valid" in self.topic("vehicle_local_position", why):
            # without a horizontal aid (no GNSS: the 8S quad's log) PX4 flags vx, vy invalid
            # and they drift to nonsense; the vertical speed (baro) and the rates still find
            # a hover
            horizontal_sq *= self.series("vehicle_local_position", "v_xy_valid", why)[1]
        speed_sq = vz**2 + horizontal_sq
        airborne = self.airborne_at(time_s)
        # averaged over HOVER_SMOOTH_S: a pilot's small corrections are hover, a manoeuvre not
        span = max(1, round(HOVER_SMOOTH_S / np.median(np.diff(time_s))))
        # a running mean of squares can dip below zero by rounding: clip before the root
        mean_speed_sq = np.maximum(uniform_filter1d(speed_sq, span), 0.0)
        steady = airborne & (np.sqrt(mean_speed_sq) <= HOVER_MAX_SPEED_MPS)
        # the collective thrust near its airborne median: the land detector calls a heavy
        # vehicle's slow spin-up airborne before it lifts (the 8S quad: 110-120 s at thrust
        # 0.2-0.55 against 0.65 in hover), and a climb without velocity (no GNSS) looks level
        if "vehicle_thrust_setpoint" in self.topics:  # else the hover's thrust names it missing
            t_thrust, thrust = self.series("vehicle_thrust_setpoint", "xyz[2]", "hover detection")
            thrust = np.interp(time_s, t_thrust, -thrust)
            median = float(np.median(thrust[airborne])) if np.any(airborne) else 0.0
            steady &= np.abs(thrust - median) <= HOVER_THRUST_BAND * median
        for axis in range(3):
            t_rate, rate = self.series("vehicle_angular_velocity", f"xyz[{axis}]",
                                       "hover detection")  # fmt: skip
            smooth = max(1, round(HOVER_SMOOTH_S / np.median(np.diff(t_rate))))
            rate_sq = np.interp(time_s, t_rate, uniform_filter1d(rate**2, smooth))
            steady &= np.sqrt(np.maximum(rate_sq, 0.0)) <= HOVER_MAX_RATE_RADPS
        windows = []
        start = None
        for t, ok in zip(time_s, np.append(steady[:-1], False), strict=True):
            if ok and start is None:
                start = t
            elif not ok and start is not None:
                if t - start >= MIN_HOVER_S:
                    windows.append((float(start), float(t)))
                start = None
        return tuple(windows)

    def _airborne_or_raise(self) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        if isinstance(self._airborne, str):
            raise LogError(f"{self.path}: {self._airborne}")
        return self._airborne.time_s, self._airborne.airborne

    def _airborne_samples(self) -> _Airborne | str:
        """Airborne or not at each sample of the land detector; without one from the arming
        state and the height or the thrust; else the one line saying what is missing."""
        if "landed" in self.topics.get("vehicle_land_detected", {}):
            time_s, landed = self.series("vehicle_land_detected", "landed", "airborne span")
            return _Airborne(time_s, landed < 0.5, "")
        missing = "no vehicle_land_detected"
        arming = self.armed_samples()
        if arming is None:
            return (
                f"{missing}, and no arming state (actuator_armed, vehicle_status) to derive "
                "the airborne span from"
            )
        if "z" in self.topics.get("vehicle_local_position", {}):
            airborne = self._airborne_by_height(*arming)
            return airborne._replace(note=f"airborne span derived ({missing}): {airborne.note}")
        if "xyz[2]" in self.topics.get("vehicle_thrust_setpoint", {}):
            airborne = self._airborne_by_thrust(*arming)
            return airborne._replace(
                note=f"airborne span derived ({missing}, no vehicle_local_position height): "
                f"{airborne.note}"
            )
        return (
            f"{missing}, and neither a height (vehicle_local_position.z) nor a thrust "
            "set-point to derive the airborne span from"
        )

    def _airborne_by_height(
        self, t_armed: NDArray[np.float64], armed: NDArray[np.bool_]
    ) -> _Airborne:
        """Armed and more than AIRBORNE_HEIGHT_M above the height of each arming's first
        ARMED_GROUND_S (a baro's offset drifts from flight to flight)."""
        time_s, down = self.series("vehicle_local_position", "z", "")
        on = _step_at(t_armed, armed, time_s)
        was_on = np.concatenate(([False], on[:-1]))
        ground = np.full(time_s.size, np.nan)
        ends = np.append(np.flatnonzero(~on & was_on), on.size)
        for start in np.flatnonzero(on & ~was_on):
            first = (time_s >= time_s[start]) & (time_s < time_s[start] + ARMED_GROUND_S)
            first[start] = True  # a height logged slower than ARMED_GROUND_S
            ground[start : ends[ends > start][0]] = np.median(down[first])
        with np.errstate(invalid="ignore"):  # NaN outside the armed spans: not airborne
            airborne = on & (ground - down > AIRBORNE_HEIGHT_M)
        return _Airborne(time_s, airborne, (
            f"armed and more than {AIRBORNE_HEIGHT_M:g} m above the height of the first "
            f"{ARMED_GROUND_S:g} s armed (vehicle_local_position.z)"
        ))  # fmt: skip

    def _airborne_by_thrust(
        self, t_armed: NDArray[np.float64], armed: NDArray[np.bool_]
    ) -> _Airborne:
        """Armed and the thrust set-point above AIRBORNE_THRUST_FRACTION of its hover level."""
        time_s, thrust = self.series("vehicle_thrust_setpoint", "xyz[2]", "")
        thrust, on = -thrust, _step_at(t_armed, armed, time_s)
        if not on.any():
            return _Airborne(time_s, on, "never armed")
        level = float(np.median(thrust[on & (thrust >= 0.5 * float(np.max(thrust[on])))]))
        return _Airborne(time_s, on & (thrust >= AIRBORNE_THRUST_FRACTION * level), (
            f"armed and the thrust set-point above {AIRBORNE_THRUST_FRACTION:g} of its hover "
            f"level {level:.2f}"
        ))  # fmt: skip

    def armed_samples(self) -> tuple[NDArray[np.float64], NDArray[np.bool_]] | None:
        """(time s, armed) from actuator_armed, else vehicle_status.arming_state; None when
        the log has neither."""
        if "armed" in self.topics.get("actuator_armed", {}):
            time_s, armed = self.series("actuator_armed", "armed", "")
            return time_s, armed > 0.5
        if "arming_state" in self.topics.get("vehicle_status", {}):
            time_s, state = self.series("vehicle_status", "arming_state", "")
            return time_s, state == ARMING_STATE_ARMED
        return None


def _step_at(
    time_s: NDArray[np.float64], values: NDArray[Any], at_s: NDArray[np.float64]
) -> NDArray[Any]:
    """The value in force at each of ``at_s`` (the first before the series starts)."""
    return values[np.clip(np.searchsorted(time_s, at_s, "right") - 1, 0, None)]


def _stamp(name: str, data: Topic) -> NDArray[np.float64]:
    """A topic's time stamps (µs): the body rates at their measurement time, so a fitted
    delay is physical."""
    measured = name == "vehicle_angular_velocity" and "timestamp_sample" in data
    return np.asarray(data["timestamp_sample" if measured else "timestamp"], dtype=float)


def _by_time(name: str, data: Topic) -> dict[str, NDArray[Any]]:
    """The topic's rows in time order (its arrays as they are when already in order)."""
    stamp = _stamp(name, data)
    if np.all(np.diff(stamp) >= 0):
        return {field: np.asarray(values) for field, values in data.items()}
    order = np.argsort(stamp, kind="stable")
    return {field: np.asarray(values)[order] for field, values in data.items()}
