"""A PX4 flight log read once per command: its topics, parameters, firmware and time span,
a topic's value at a time, and the spans every tool of a flight needs (armed, airborne,
steady hover).

Why one reader: identification, the wind estimate, the vibration fit and a replay all ask
the same log the same questions; each parsing it again cost seconds and gave each its own
error wording. Topics are the first instance (``multi_id`` 0), each row-sorted by its time;
a topic a newer PX4 has and an older log lacks is derived from what the log holds
(:mod:`px4_logs.layouts`) and the note says how.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Self

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter1d

from px4_logs.errors import LogError
from px4_logs.layouts import derive_missing
from px4_logs.ulog import firmware_name, read_ulog

#: Steady hover: airborne, RMS over HOVER_SMOOTH_S of |v| and of each body rate below these,
#: for at least MIN_HOVER_S (a position-hold hover with a pilot's small corrections qualifies).
HOVER_SMOOTH_S = 1.0
HOVER_MAX_SPEED_MPS = 0.6
HOVER_MAX_RATE_RADPS = 0.25
MIN_HOVER_S = 3.0
#: … and the thrust set-point within this fraction of its airborne median.
HOVER_THRUST_BAND = 0.2

Topic = Mapping[str, NDArray[Any]]


class FlightLog:
    """The parts of a PX4 ULog the rig's tools read, with one-line errors naming file and field."""

    def __init__(
        self,
        path: str | Path,
        topics: Mapping[str, Mapping[str, NDArray[Any]]],
        parameters: Mapping[str, float],
        *,
        firmware: str = "",
        warnings: tuple[str, ...] = (),
        first_s: float | None = None,
        last_s: float | None = None,
    ) -> None:
        """A log from its topics (field → array, each with its ``timestamp`` in µs):
        :meth:`read` parses a file; a test or a tool can build one in memory."""
        self.path = Path(path)
        self.parameters = dict(parameters)
        self.firmware = firmware
        self.warnings = warnings  # pyulog's, become a run's notes
        own = {name: dict(data) for name, data in topics.items()}  # derive_missing adds to it
        if not own:
            raise LogError(f"{self.path}: the ULog holds no logged data")
        first_us = min(float(data["timestamp"][0]) for data in own.values())
        self.first_s = first_us / 1e6 if first_s is None else first_s
        last_us = max(float(data["timestamp"][-1]) for data in own.values())
        self.last_s = last_us / 1e6 if last_s is None else last_s
        #: Notes of the topics derived from an older PX4's layout.
        self.derived = derive_missing(own, self.parameters)
        self.topics: dict[str, dict[str, NDArray[Any]]] = {}
        self._time_s: dict[str, NDArray[np.float64]] = {}
        for name, data in own.items():
            # the body rates at their measurement time, so a fitted delay is physical
            measured = name == "vehicle_angular_velocity" and "timestamp_sample" in data
            stamp = np.asarray(data["timestamp_sample" if measured else "timestamp"])
            order = np.argsort(stamp, kind="stable")
            self.topics[name] = {field: np.asarray(v)[order] for field, v in data.items()}
            self._time_s[name] = stamp[order] * 1e-6

    @classmethod
    def read(cls, path: str | Path) -> Self:
        """Parse a ULog file (the first instance of each topic)."""
        path = Path(path)
        if not path.is_file():
            raise LogError(f"{path}: flight log not found")
        ulog, warnings = read_ulog(path)
        # A topic's first sample may be its last one before the logger started (published
        # at boot: the 8S quad's actuator_outputs at 0.6 s, logging from 104.9 s); the
        # header's start time bounds the logged span (0 in some logs, the X500's).
        first_us = min((float(d.data["timestamp"][0]) for d in ulog.data_list), default=0.0)
        last_us = max((float(d.data["timestamp"][-1]) for d in ulog.data_list), default=0.0)
        return cls(
            path,
            {d.name: d.data for d in ulog.data_list if d.multi_id == 0},
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
        """First to last sample the land detector called airborne."""
        time_s, landed = self.series("vehicle_land_detected", "landed", "airborne span")
        flying = time_s[landed < 0.5]
        if flying.size == 0:
            raise LogError(f"{self.path}: the vehicle never left the ground")
        return float(flying[0]), float(flying[-1])

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
        t_landed, landed = self.series("vehicle_land_detected", "landed", "airborne span")
        landed_now = landed[np.clip(np.searchsorted(t_landed, time_s, "right") - 1, 0, None)]
        # averaged over HOVER_SMOOTH_S: a pilot's small corrections are hover, a manoeuvre not
        span = max(1, round(HOVER_SMOOTH_S / np.median(np.diff(time_s))))
        # a running mean of squares can dip below zero by rounding: clip before the root
        mean_speed_sq = np.maximum(uniform_filter1d(speed_sq, span), 0.0)
        steady = (landed_now < 0.5) & (np.sqrt(mean_speed_sq) <= HOVER_MAX_SPEED_MPS)
        # the collective thrust near its airborne median: the land detector calls a heavy
        # vehicle's slow spin-up airborne before it lifts (the 8S quad: 110-120 s at thrust
        # 0.2-0.55 against 0.65 in hover), and a climb without velocity (no GNSS) looks level
        if "vehicle_thrust_setpoint" in self.topics:  # else the hover's thrust names it missing
            t_thrust, thrust = self.series("vehicle_thrust_setpoint", "xyz[2]", "hover detection")
            thrust = np.interp(time_s, t_thrust, -thrust)
            airborne = landed_now < 0.5
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
