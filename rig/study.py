"""``rig study LOG``: one command from a PX4 multicopter log to a credibility verdict.

A study is four stages, each kept in the study folder, so an interrupted study resumes at
the first stage it had not finished (as ``make credibility`` does) and a finished one is
reported again without flying:

1. **vehicle** (``vehicle.toml``): ``--vehicle``, else the bundled vehicle of the log's
   airframe (``SYS_AUTOSTART``), else one written from the log (``rig vehicle``, which
   needs the mass the log cannot give: ``--mass``).
2. **replay** (``replay/``): the flight through PX4 SITL with the log's own parameters,
   sticks, modes and mission when a PX4 build is given (``--px4``), else through the
   reference autopilot, which flies the log's velocity set-points or, for a flight without
   a horizontal position (no GNSS, a manual attitude mode), its attitude set-points.
3. **plan** (``plan.toml``): ``credibility plan``: the segments the paper's tests need,
   found in the log, the replay's autopilot log as the sim; the tests the log cannot
   support are listed with the reason.
4. **report** (``report/``): ``credibility report``: the indices, η_all, η_min, the HTML.

``study.json`` records what the study was started with (the log's SHA-256, the vehicle,
the autopilot); a folder holding another study is refused unless ``--force``.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from credibility import assess, load_plan
from credibility.autoplan import write_plan
from credibility.autoplan.responses import pilot_spans
from credibility.report import exit_code, write_report
from px4_logs import FlightLog, LogError
from quad_model.vehicle import (
    VEHICLES_DIR,
    VehicleFileError,
    load_vehicle,
    vehicle_for_airframe,
)
from rig.autopilots import Autopilot
from rig.errors import RigError
from rig.identify.vehicle_file import vehicle_from_log
from rig.lockstep.loop import AUTOPILOT_LOGS, Progress, RunOptions
from rig.replay import Drive, ReplayOptions, plan_replay, run_replay

#: What a study folder holds: its inputs, then one output per stage.
STUDY_FILE = "study.json"
VEHICLE_FILE = "vehicle.toml"
REPLAY_DIR = "replay"
PLAN_FILE = "plan.toml"
REPORT_DIR = "report"
#: A finished replay's stamp (a replay stopped midway leaves readable logs, not this).
COMPLETE = ".complete"
#: The attitude drive takes over this long before lift-off, so the replay's own take-off
#: transient is settled when the flight's first segment starts, and hands back at landing.
ATTITUDE_LEAD_S = 1.0
#: A flight whose velocity set-points are finite less than this share of its airborne time
#: was flown without them (Stabilized, Acro, no GNSS): the attitude set-points drive it.
MIN_VELOCITY_SETPOINT_SHARE = 0.5


class StudyError(RigError):
    """A study cannot go on (its folder holds another study, no vehicle can be had, ...)."""


@dataclass(frozen=True)
class StudyInputs:
    """What a study is of; a study folder holds exactly one."""

    log: str
    log_sha256: str
    #: A vehicle name or file, ``"bundled"``, or ``"from the log"``.
    vehicle: str
    mass_kg: float | None
    autopilot: str
    px4_dir: str | None


@dataclass(frozen=True)
class Verdict:
    """The report's verdict in one line, and where the report is."""

    outcome: str
    eta_all: float | None
    eta_min: float | None
    scored: int
    tests: int
    not_scorable: int
    html: Path
    exit_code: int
    #: Why there are no indices ("" when there are).
    unscorable_reason: str = ""

    def line(self) -> str:
        indices = (
            f"η_all {self.eta_all:.1%}, η_min {self.eta_min:.1%}"
            if self.eta_all is not None and self.eta_min is not None
            else f"no indices ({self.unscorable_reason})"
        )
        return (
            f"{self.outcome}: {indices} ({self.scored} of {self.tests} tests scored, "
            f"{self.not_scorable} not scorable from this log) → {self.html}"
        )


class Study:
    """One log's study in one folder: call the stages in order; each skips itself when done."""

    def __init__(
        self,
        log_path: Path,
        out_dir: Path,
        *,
        vehicle: str | None = None,
        mass_kg: float | None = None,
        px4_dir: Path | None = None,
        instance: int = 0,
        force: bool = False,
    ) -> None:
        if vehicle is not None and mass_kg is not None:
            raise StudyError(
                "--vehicle and --mass: give one (--mass writes the vehicle file from the log)"
            )
        if mass_kg is not None and not (math.isfinite(mass_kg) and mass_kg > 0):
            raise StudyError(f"--mass {mass_kg:g}: a vehicle's mass is a positive number of kg")
        self.log = FlightLog.read(log_path)
        self.out_dir = out_dir
        self.instance = instance
        self.px4_dir = px4_dir
        self.autopilot = Autopilot.PX4 if px4_dir is not None else Autopilot.REFERENCE
        self.vehicle_choice = vehicle
        self.mass_kg = mass_kg
        self.inputs = StudyInputs(
            log=str(self.log.path.resolve()),
            log_sha256=hashlib.sha256(self.log.path.read_bytes()).hexdigest(),
            vehicle=vehicle or ("from the log" if mass_kg is not None else "bundled"),
            mass_kg=mass_kg,
            autopilot=str(self.autopilot),
            px4_dir=str(px4_dir.resolve()) if px4_dir is not None else None,
        )
        self._claim(force)

    def _claim(self, force: bool) -> None:
        """The folder for this study: new, this study's (resumed), or refused."""
        record = self.out_dir / STUDY_FILE
        if record.exists() and not force:
            try:
                held = json.loads(record.read_text(encoding="utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as error:
                raise StudyError(
                    f"{record}: not a study's record ({error}); pass --force to start over"
                ) from None
            recorded = held if isinstance(held, dict) else {}
            if recorded != asdict(self.inputs):
                differ = sorted(k for k, v in asdict(self.inputs).items() if recorded.get(k) != v)
                raise StudyError(
                    f"{self.out_dir}: holds a study of other inputs ({', '.join(differ)} "
                    "differ); choose another --out, or pass --force to start over"
                )
            return
        if force:
            for stage in (VEHICLE_FILE, PLAN_FILE, f"{REPLAY_DIR}/{COMPLETE}"):
                (self.out_dir / stage).unlink(missing_ok=True)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        record.write_text(json.dumps(asdict(self.inputs), indent=2) + "\n", encoding="utf-8")

    # --- 1. vehicle --------------------------------------------------------------------------

    @property
    def vehicle_path(self) -> Path:
        return self.out_dir / VEHICLE_FILE

    def vehicle(self) -> str:
        """Write ``vehicle.toml`` (unless done); says where the vehicle came from."""
        if self.vehicle_path.exists():
            return f"{self.vehicle_path} (kept from the earlier run)"
        if self.vehicle_choice is not None:
            text, origin = self._given_vehicle(self.vehicle_choice), self.vehicle_choice
        elif self.mass_kg is not None:
            window = excitation_window(self.log)
            command = f"rig study {self.log.path.name} --mass {self.mass_kg:g}"
            text = vehicle_from_log(self.log, self.mass_kg, command, window).toml()
            origin = f"written from the log with mass {self.mass_kg:g} kg" + (
                f", the rate plant fitted over the pilot's {window[0]:.1f}-{window[1]:.1f} s"
                if window
                else ", no pilot-flown span to fit the rate plant: the generic inertia"
            )
        else:
            try:
                name = vehicle_for_airframe(self.log.parameters, self.log.path)
            except VehicleFileError as error:
                raise StudyError(
                    f"{error}; or --mass KG to write a vehicle file from the log"
                ) from None
            text, origin = self._given_vehicle(name), f"{name}, bundled for the log's airframe"
        _write_atomically(self.vehicle_path, text)
        return f"{self.vehicle_path} ({origin})"

    @staticmethod
    def _given_vehicle(name_or_path: str) -> str:
        """A vehicle file's text, checked by loading it first (a bad file fails here)."""
        load_vehicle(name_or_path)
        path = Path(name_or_path)
        if not path.is_file():
            path = VEHICLES_DIR / f"{name_or_path}.toml"
        return path.read_text(encoding="utf-8")

    # --- 2. replay ---------------------------------------------------------------------------

    @property
    def replay_dir(self) -> Path:
        return self.out_dir / REPLAY_DIR

    @property
    def sim_log(self) -> Path:
        """The replay's autopilot log: what a real flight logs, so what the plan scores."""
        name = AUTOPILOT_LOGS[0] if self.autopilot is Autopilot.PX4 else AUTOPILOT_LOGS[1]
        return self.replay_dir / name

    def replay_options(self) -> ReplayOptions:
        """PX4 as the pilot flew it, or the reference autopilot on the set-points it can fly."""
        vehicle = str(self.vehicle_path.resolve())
        if self.autopilot is Autopilot.PX4:
            return ReplayOptions(vehicle=vehicle, autopilot=Autopilot.PX4, px4_dir=self.px4_dir)
        drive, window = reference_drive(self.log)
        return ReplayOptions(drive=drive, window_s=window, vehicle=vehicle)

    def replay(self, progress: Callable[[Progress], None] | None = None) -> str | None:
        """Fly the replay (unless done); None when it was done before, else what flew."""
        if (self.replay_dir / COMPLETE).exists():
            return None
        options = self.replay_options()
        replay = plan_replay(self.log.path, options)
        result = run_replay(
            replay,
            RunOptions(out_dir=self.replay_dir, force=True, instance=self.instance),
            progress,
        )
        (self.replay_dir / COMPLETE).touch()
        how = "as its pilot flew it" if replay.px4 else f"{replay.drive} drive"
        return (
            f"{result.autopilot}, {how}, {result.simulated_s:.1f} s simulated in "
            f"{result.wall_s:.1f} s → {self.sim_log}"
        )

    # --- 3. plan -----------------------------------------------------------------------------

    @property
    def plan_path(self) -> Path:
        return self.out_dir / PLAN_FILE

    def plan(self) -> str:
        """Write ``plan.toml`` (unless done): the tests this log supports and why not the rest."""
        if self.plan_path.exists():
            return f"{self.plan_path} (kept from the earlier run)"
        write_plan(self.log, self.plan_path, sim=self.sim_log)
        plan = load_plan(self.plan_path)
        return (
            f"{self.plan_path}: {len(plan.tests)} tests, {len(plan.not_scorable)} not "
            "scorable from this log"
        )

    # --- 4. report ---------------------------------------------------------------------------

    def report(self, advance: Callable[[str], None] | None = None) -> Verdict:
        """Score the replay with the plan; the report goes to ``report/`` (always redone:
        it is seconds, and a plan edited by hand must count)."""
        plan = load_plan(self.plan_path)
        assessment = assess(plan, advance or (lambda _label: None), strict=False)
        html, _ = write_report(assessment, self.out_dir / REPORT_DIR)
        return Verdict(
            outcome=assessment.outcome,
            eta_all=assessment.eta_all,
            eta_min=assessment.eta_min,
            scored=len(assessment.results),
            tests=len(plan.tests),
            not_scorable=len(plan.not_scorable),
            html=html,
            exit_code=int(exit_code(assessment)),
            unscorable_reason=assessment.unscorable_reason or "",
        )


def reference_drive(log: FlightLog) -> tuple[Drive, tuple[float, float] | None]:
    """The reference autopilot's drive for a log: its velocity set-points over the whole
    flight when it has them, else its attitude set-points from just before lift-off to the
    landing (a Stabilized flight, or one without GNSS, whose velocities are not a
    measurement)."""
    airborne = log.airborne_span()
    try:
        time_s, vx = log.series("vehicle_local_position_setpoint", "vx", "")
    except LogError:
        time_s, vx = np.zeros(0), np.zeros(0)
    inside = (time_s >= airborne[0]) & (time_s <= airborne[1])
    share = float(np.mean(np.isfinite(vx[inside]))) if np.any(inside) else 0.0
    if share >= MIN_VELOCITY_SETPOINT_SHARE:
        return Drive.VELOCITY, None
    armed_at = log.armed_span()[0]
    return Drive.ATTITUDE, (max(airborne[0] - ATTITUDE_LEAD_S, armed_at + ATTITUDE_LEAD_S),
                            airborne[1])  # fmt: skip


def excitation_window(log: FlightLog) -> tuple[float, float] | None:
    """The pilot-flown span with the most stick input (the plan's rate responses use the
    same): the only excitation of a flight without a sweep, for the inertia and motor lag.
    None when the log has none."""
    try:
        spans = pilot_spans(log)
    except LogError:
        return None
    return spans[0] if spans else None


def _write_atomically(path: Path, text: str) -> None:
    """A stage's output appears whole or not at all, so a resumed study trusts it."""
    partial = path.with_suffix(path.suffix + ".partial")
    partial.write_text(text, encoding="utf-8")
    partial.replace(path)
