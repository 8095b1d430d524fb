"""Reading logs: ULog (real PX4 flights, PX4 SITL, the rig) and CSV/Parquet tables.

A signal is named ``topic[.instance].field`` (``sensor_accel.1.x``,
``vehicle_angular_velocity.xyz[0]``). A field ``<array>.roll|pitch|yaw`` of a quaternion
array (``vehicle_attitude.q.pitch``, ``vehicle_attitude_setpoint.q_d.roll``) is derived as
the ZYX Euler angle in radians (PX4's Hamilton quaternion, w first); yaw is unwrapped so it
is a continuous curve. ``vehicle_local_position.v_forward|v_right`` is the horizontal
velocity along the vehicle's heading and to its right (from ``vx``, ``vy`` and
``heading``): the axes a pilot's sticks command in Position mode, so a replay whose heading
differs compares the response, not the heading. Tables hold a time column (``timestamp``
in µs, as PX4 logs it, or ``time_s``) and one column per signal, named exactly like the
plan's signal path.
"""

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field
from scipy.spatial.transform import Rotation

from credibility.errors import CredibilityError, NotScorable
from credibility.signals import Signal
from hil_config import Number, table
from px4_logs import LogError, read_ulog

_EULER = ("roll", "pitch", "yaw")
#: Derived fields of the horizontal velocity in the heading frame (see the module docstring).
_HEADING_FRAME = ("v_forward", "v_right")
_PATH = re.compile(r"^(?P<topic>[A-Za-z_][\w]*)(?:\.(?P<instance>\d+))?\.(?P<field>[\w.\[\]]+)$")

#: Named unit conversions a plan may apply (factor multiplies the logged value).
Conversion = Literal[
    "rad->deg", "deg->rad", "rad/s->deg/s", "deg/s->rad/s", "m/s2->g", "g->m/s2", "us->s"
]
CONVERSIONS: dict[Conversion, float] = {
    "rad->deg": 180.0 / np.pi,
    "deg->rad": np.pi / 180.0,
    "rad/s->deg/s": 180.0 / np.pi,
    "deg/s->rad/s": np.pi / 180.0,
    "m/s2->g": 1.0 / 9.80665,  # standard gravity, ISO 80000-3
    "g->m/s2": 9.80665,
    "us->s": 1e-6,
}


@table
class SignalSpec:
    """Where a signal lives in a log and how to convert it to the plan's units."""

    #: ``topic[.instance].field``
    path: Annotated[str, Field(strict=True, pattern=_PATH.pattern)]
    scale: Number = 1.0
    convert: Conversion | None = None
    #: Drop the samples that are NaN (a topic logged with gaps) instead of failing.
    drop_nan: Annotated[bool, Field(strict=True)] = False

    @property
    def factor(self) -> float:
        return self.scale * (CONVERSIONS[self.convert] if self.convert else 1.0)

    def parts(self) -> tuple[str, int, str]:
        """(topic, instance, field); the instance is 0 unless the path names one."""
        match = _PATH.match(self.path)
        if match is None:
            raise CredibilityError(
                f"signal {self.path!r} is not of the form topic[.instance].field"
            )
        return match["topic"], int(match["instance"] or 0), match["field"]


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        for chunk in iter(lambda: stream.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


@dataclass(frozen=True, eq=False)
class LogFile:
    """One opened log: its topics as arrays, its hash, and what the reader warned about."""

    path: Path
    sha256: str
    format: str
    #: (topic, instance) → field name → values; every topic has "timestamp_s".
    topics: dict[tuple[str, int], dict[str, np.ndarray]]
    warnings: tuple[str, ...]

    def signal(self, spec: SignalSpec) -> Signal:
        """The signal ``spec`` names, converted, sorted by time with duplicate stamps dropped."""
        topic, instance, field = spec.parts()
        fields = self.topics.get((topic, instance))
        if fields is None:
            known = sorted({f"{t}.{i}" if i else t for t, i in self.topics})
            hint = ", ".join(k for k in known if k.split(".")[0] == topic) or ", ".join(known[:12])
            raise NotScorable(
                "missing_topic",
                f"{self.path}: no topic {topic!r} instance {instance} (signal {spec.path!r}); "
                f"available: {hint}",
            )
        values = _field_values(fields, field, spec.path, self.path)
        time_s = fields["timestamp_s"]
        steps = np.diff(time_s)
        if np.any(steps <= 0.0):  # out of order or repeated stamps: sort, keep the first
            order = np.argsort(time_s, kind="stable")
            time_s, values = time_s[order], values[order]
            keep = np.concatenate(([True], np.diff(time_s) > 0.0))
            time_s, values = time_s[keep], values[keep]
        return Signal(spec.path, str(self.path), time_s, values * spec.factor)


def _field_values(fields: dict[str, np.ndarray], field: str, name: str, path: Path) -> np.ndarray:
    if field in fields:
        return fields[field].astype(float)
    base, _, angle = field.rpartition(".")
    quaternion = [f"{base}[{i}]" for i in range(4)]
    if angle in _EULER and all(q in fields for q in quaternion):
        return euler_zyx(*(fields[q].astype(float) for q in quaternion))[_EULER.index(angle)]
    if field in _HEADING_FRAME and all(f in fields for f in ("vx", "vy", "heading")):
        forward, right = heading_frame(
            fields["vx"].astype(float), fields["vy"].astype(float), fields["heading"].astype(float)
        )
        return forward if field == "v_forward" else right
    listed = ", ".join(sorted(f for f in fields if f != "timestamp_s")[:20])
    raise NotScorable(
        "missing_topic", f"{path}: no field {field!r} (signal {name!r}); fields: {listed}"
    )


def heading_frame(
    north: np.ndarray, east: np.ndarray, heading: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(forward, right): a horizontal NED velocity along the heading (rad) and to its right."""
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    return north * cos_h + east * sin_h, east * cos_h - north * sin_h


def euler_zyx(
    w: np.ndarray, x: np.ndarray, y: np.ndarray, z: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZYX (yaw-pitch-roll) angles of a Hamilton quaternion, as PX4's matrix::Euler; yaw
    unwrapped. scipy's Rotation, so credibility needs no other package's conventions."""
    rotation = Rotation.from_quat(np.column_stack((x, y, z, w)))  # scipy: scalar last
    yaw, pitch, roll = rotation.as_euler("ZYX").T
    return roll, pitch, np.unwrap(yaw)


def open_log(path: Path) -> LogFile:
    """Open a ULog, CSV or Parquet file, chosen by its suffix."""
    path = Path(path)
    if not path.is_file():
        raise CredibilityError(f"{path}: log file not found")
    suffix = path.suffix.lower()
    if suffix == ".ulg":
        topics, warnings = _read_ulog(path)
        fmt = "ulog"
    elif suffix in (".csv", ".parquet", ".pq"):
        topics, warnings = _read_table(path), ()
        fmt = "csv" if suffix == ".csv" else "parquet"
    else:
        raise CredibilityError(f"{path}: unknown log format {suffix!r} (use .ulg, .csv, .parquet)")
    return LogFile(path, sha256_of(path), fmt, topics, warnings)


def _read_ulog(path: Path) -> tuple[dict, tuple[str, ...]]:
    try:
        ulog, warnings = read_ulog(path)
    except LogError as error:
        raise CredibilityError(str(error)) from None
    topics = {}
    for dataset in ulog.data_list:
        fields = dict(dataset.data)
        fields["timestamp_s"] = fields["timestamp"] * 1e-6
        topics[(dataset.name, dataset.multi_id)] = fields
    if not topics:
        raise CredibilityError(
            f"{path}: ULog has no logged data (the file is truncated or was never written)"
        )
    return topics, warnings


def _read_table(path: Path) -> dict:
    import pandas as pd  # on demand: pandas and pyarrow cost ~100 MiB a ULog reader never needs

    try:
        frame = pd.read_csv(path) if path.suffix.lower() == ".csv" else pd.read_parquet(path)
    except (ValueError, OSError, pd.errors.ParserError) as exc:
        raise CredibilityError(f"{path}: not a readable table ({exc})") from None
    if "time_s" in frame:
        time_s = frame["time_s"].to_numpy(dtype=float)
    elif "timestamp" in frame:
        time_s = frame["timestamp"].to_numpy(dtype=float) * 1e-6
    else:
        raise CredibilityError(f"{path}: no time column; expected 'time_s' (s) or 'timestamp' (µs)")
    topics: dict[tuple[str, int], dict[str, np.ndarray]] = {}
    for column in frame.columns:
        match = _PATH.match(str(column))
        if match is None:
            continue
        key = (match["topic"], int(match["instance"] or 0))
        fields = topics.setdefault(key, {"timestamp_s": time_s})
        fields[match["field"]] = frame[column].to_numpy(dtype=float)
    if not topics:
        raise CredibilityError(
            f"{path}: no signal columns; name them topic[.instance].field, e.g. "
            "'vehicle_angular_velocity.xyz[0]'"
        )
    return topics
