"""The results store: one SQLite row per finished case, committed as it finishes, so a rerun
skips what is done and an interrupt never leaves half a row."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from rig.campaign.schema import CampaignError, CredibilityScoring

RESULTS_DB = "results.sqlite"


#: Case outcomes: ``ok`` and ``failed`` ran to the end (criteria met or not), ``crashed``
#: is a run that ended in an error, ``hung`` one killed by the per-case timeout.
STATUSES = ("ok", "failed", "crashed", "hung")


@dataclass(frozen=True)
class CaseResult:
    case_id: str
    index: int
    labels: tuple[tuple[str, str], ...]
    status: str
    reason: str
    metrics: Mapping[str, Any]
    wall_s: float
    run_dir: str
    rig_log: str | None
    autopilot_log: str | None


class ResultsDb:
    """``results.sqlite``: one row per finished case, each written in its own transaction."""

    _SCHEMA = """CREATE TABLE IF NOT EXISTS cases (
        case_id TEXT PRIMARY KEY, case_index INTEGER NOT NULL, axes_json TEXT NOT NULL,
        status TEXT NOT NULL, reason TEXT NOT NULL, metrics_json TEXT NOT NULL,
        wall_s REAL NOT NULL, run_dir TEXT NOT NULL, rig_log TEXT, autopilot_log TEXT,
        finished_utc TEXT NOT NULL)"""
    #: What holds for the whole campaign (the credibility plan's path and SHA-256).
    _PROVENANCE_SCHEMA = """CREATE TABLE IF NOT EXISTS provenance (
        key TEXT PRIMARY KEY, value TEXT NOT NULL)"""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self.connection = sqlite3.connect(path)
            self.connection.execute("PRAGMA journal_mode=WAL")
            with self.connection:
                self.connection.execute(self._SCHEMA)
                self.connection.execute(self._PROVENANCE_SCHEMA)
        except sqlite3.DatabaseError as error:
            raise CampaignError(f"{path}: not a campaign results database ({error})") from None

    def __enter__(self) -> ResultsDb:
        return self

    def __exit__(self, *_: object) -> None:
        self.connection.close()

    def finished_ids(self) -> set[str]:
        return {row[0] for row in self.connection.execute("SELECT case_id FROM cases")}

    def provenance(self) -> dict[str, str]:
        return dict(self.connection.execute("SELECT key, value FROM provenance"))

    def record_plan(self, scoring: CredibilityScoring) -> None:
        """Keep the plan's hash once; scores from another version of the plan in the same
        results would not be comparable, so that is refused."""
        recorded = self.provenance().get("credibility_plan_sha256")
        if recorded not in (None, scoring.plan_sha256) and self.finished_ids():
            raise CampaignError(
                f"{self.path}: its cases were scored with credibility plan sha256 "
                f"{recorded}, but {scoring.plan_path} is now {scoring.plan_sha256}; "
                "use a new results folder"
            )
        with self.connection:
            self.connection.executemany(
                "INSERT OR REPLACE INTO provenance VALUES (?, ?)",
                [
                    ("credibility_plan", scoring.plan_path),
                    ("credibility_plan_sha256", scoring.plan_sha256),
                    ("credibility_role", scoring.role),
                    ("credibility_log", scoring.log),
                ],
            )

    def record(self, result: CaseResult) -> None:
        with self.connection:  # one transaction: the row is all there or not at all
            self.connection.execute(
                "INSERT OR REPLACE INTO cases VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    result.case_id,
                    result.index,
                    json.dumps(dict(result.labels)),
                    result.status,
                    result.reason,
                    json.dumps(result.metrics, sort_keys=True),
                    result.wall_s,
                    result.run_dir,
                    result.rig_log,
                    result.autopilot_log,
                    datetime.now(UTC).isoformat(timespec="seconds"),
                ),
            )

    def results(self) -> list[CaseResult]:
        rows = self.connection.execute(
            "SELECT case_id, case_index, axes_json, status, reason, metrics_json, wall_s, "
            "run_dir, rig_log, autopilot_log FROM cases ORDER BY case_index"
        )
        return [
            CaseResult(
                case_id=case_id,
                index=index,
                labels=tuple(json.loads(axes_json).items()),
                status=status,
                reason=reason,
                metrics=json.loads(metrics_json),
                wall_s=wall_s,
                run_dir=run_dir,
                rig_log=rig_log,
                autopilot_log=autopilot_log,
            )
            for (case_id, index, axes_json, status, reason, metrics_json, wall_s, run_dir,
                 rig_log, autopilot_log) in rows
        ]  # fmt: skip


def read_results(out_dir: Path) -> list[CaseResult]:
    with _open_results(out_dir) as db:
        return db.results()


def read_provenance(out_dir: Path) -> dict[str, str]:
    """What the campaign recorded once for all its cases (empty without credibility)."""
    with _open_results(out_dir) as db:
        return db.provenance()


def _open_results(out_dir: Path) -> ResultsDb:
    path = out_dir / RESULTS_DB
    if not path.is_file():
        raise CampaignError(f"{path}: no campaign results here")
    return ResultsDb(path)
