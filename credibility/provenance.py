"""Where each log of a report came from: the firmware its header names and, for a rig
replay's log, the run's ``replay.json`` beside it (the flight it replays, the vehicle model,
the parameters applied, skipped or set by the rig, the wind flown).

A score says how close a simulation came to a flight; it means something only together with
which firmware flew on each side, with whose parameters and on which model, so the report
shows these next to the indices instead of leaving them in the run folders.
"""

from __future__ import annotations

import contextlib
import io
import json
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from pyulog import ULog
from pyulog.core import ULogException

from px4_logs import firmware_name

#: What ``rig replay`` writes beside the logs of its run (rig.replay.Replay.summary).
REPLAY_SUMMARY = "replay.json"


@dataclass(frozen=True)
class Provenance:
    """One log's origin; ``firmware`` None for a log without a ULog header (CSV, Parquet)."""

    firmware: str | None
    #: The run's replay.json when the log sits in a ``rig replay`` run folder.
    replay: Mapping[str, Any] | None

    def to_dict(self) -> dict[str, Any]:
        replay = self.replay
        if replay is None:
            return {"firmware": self.firmware, "replay": None}
        return {
            "firmware": self.firmware,
            "replay": {
                "replays": replay.get("log"),
                "autopilot": replay.get("autopilot"),
                "flown_by": replay.get("log_firmware"),
                "vehicle_model": replay.get("vehicle"),
                "parameters_applied": len(replay.get("parameters_applied", {})),
                "parameters_skipped": _skipped_by_reason(replay),
                "parameters_set_by_the_rig": replay.get("parameters_set_by_the_rig", {}),
                "wind": replay.get("wind"),
                "imu_hz": replay.get("imu_hz"),
                "seed": replay.get("seed"),
                "summary": str(replay.get("_path")),
            },
        }

    def describe(self) -> dict[str, str]:
        """The HTML table's cells: firmware, what was replayed on which model, parameters,
        wind."""
        data = self.to_dict()
        replay = data["replay"]
        if replay is None:
            return {"firmware": self.firmware or "—", "replay": "—", "parameters": "—", "wind": "—"}
        skipped = replay["parameters_skipped"]
        wind = replay["wind"]
        if isinstance(wind, Mapping):
            wind = (
                f"{wind['speed_mps']:.1f} ± {wind['bound_mps']:.1f} m/s from "
                f"{wind['from_deg']:.0f}° ({wind['method']})"
            )
        return {
            "firmware": self.firmware or "—",
            "replay": (
                f"{Path(str(replay['replays'])).name} (flown by {replay['flown_by'] or '?'}) "
                f"by {replay['autopilot']} on vehicle model {replay['vehicle_model']}, "
                f"IMU {replay['imu_hz'] or 'default'} Hz, seed {replay['seed']}"
            ),
            "parameters": (
                f"{replay['parameters_applied']} of the flight's applied, "
                f"{sum(len(v) for v in skipped.values())} skipped ("
                + "; ".join(f"{reason}: {len(names)}" for reason, names in skipped.items())
                + f"), {len(replay['parameters_set_by_the_rig'])} set by the rig ("
                + ", ".join(f"{k} {v:g}" for k, v in replay["parameters_set_by_the_rig"].items())
                + f"); {replay['summary']} lists each"
            ),
            "wind": str(wind),
        }


def _skipped_by_reason(replay: Mapping[str, Any]) -> dict[str, list[str]]:
    grouped: dict[str, list[str]] = {}
    for skipped in replay.get("parameters_skipped", []):
        grouped.setdefault(str(skipped.get("reason")), []).append(str(skipped.get("name")))
    return grouped


@lru_cache(maxsize=32)
def provenance_of(path: Path, fmt: str) -> Provenance:
    """The firmware in ``path``'s ULog header and the replay.json beside it, when there."""
    firmware = None
    if fmt == "ulog":
        with contextlib.redirect_stdout(io.StringIO()):  # pyulog prints what it skips
            try:
                info = ULog(str(path), [], parse_header_only=True).msg_info_dict
            # what pyulog raises on a damaged file (px4_logs.read_ulog): no firmware
            except (ULogException, ValueError, IndexError, KeyError, struct.error, UnicodeError,
                    OSError):  # fmt: skip
                info = {}
        firmware = firmware_name(info) if "ver_sw_release" in info else None
    summary_path = path.parent / REPLAY_SUMMARY
    replay = None
    if summary_path.is_file():
        try:
            replay = json.loads(summary_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            replay = {"log": f"{summary_path} is not readable JSON"}
        replay["_path"] = str(summary_path)
    return Provenance(firmware, replay)
