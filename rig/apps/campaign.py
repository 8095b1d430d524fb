"""Campaigns: a base scenario swept over axes, every case a real rig run, results in SQLite.

A campaign file (TOML) names a base scenario, the axes to sweep (fault × onset × severity,
wind, mass and inertia, motor constants, IMU noise, seeds, autopilot parameters), the
pass criteria and the run settings. :func:`expand` turns it into the Cartesian product of
cases; :func:`run_campaign` runs them on any ``concurrent.futures.Executor`` (a local
process pool, or Dask's ``Client.get_executor()``) and commits one row per case to
``results.sqlite`` as each finishes, so a rerun skips what is done and Ctrl-C never
leaves a half-written row.

Each case runs in its own ``python -m rig.apps.campaign_case`` process (its own ports, its own
autopilot) under a wall-clock timeout, so a crash or a hang costs that case only: it is
recorded with its reason and the campaign goes on. The case folder holds the scenario
and vehicle files it flew (``rig run CASE/scenario.toml`` replays it) and its logs.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import itertools
import json
import os
import sqlite3
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import tomli_w
from pydantic import Field

from credibility import CredibilityError, load_plan
from hil_config import (
    FieldError,
    NonNegative,
    NonNegativeInteger,
    Number,
    Positive,
    PositiveInteger,
    Text,
    parse,
    read_toml,
    table,
)
from quad_model.vehicle import VEHICLES_DIR, VehicleFileError, vehicle_from_dict
from rig.errors import RigError
from rig.processes import restore_sigint, stop_process_group
from rig.scenarios.scenario import SCENARIOS_DIR, FaultSpec, SensorLayer, scenario_from_dict

T = TypeVar("T")

CAMPAIGNS_DIR = Path(__file__).parent / "campaigns"
PLANS_DIR = Path(__file__).parents[2] / "credibility" / "plans"
RESULTS_DB = "results.sqlite"
#: Case outcomes: ``ok`` and ``failed`` ran to the end (criteria met or not), ``crashed``
#: is a run that ended in an error, ``hung`` one killed by the per-case timeout.
STATUSES = ("ok", "failed", "crashed", "hung")
#: What each case reports (rig.apps.campaign_case computes them from the run's logs).
METRICS = (
    "max_tilt_deg",
    "altitude_loss_m",
    "time_to_failsafe_s",
    "impact_speed_mps",
    "crashed",
    "eta_all",
    "eta_min",
)
#: The metrics only a campaign with a ``[credibility]`` table measures.
CREDIBILITY_METRICS = ("eta_all", "eta_min")
#: Which of a case's logs can fill the credibility plan's role.
CASE_LOGS = ("rig", "autopilot")
#: Grace after SIGINT for a timed-out case to close its logs and stop its autopilot.
STOP_GRACE_S = 10.0

#: Vehicle axes: ``axis → (section, keys)``; the value scales those vehicle-file entries.
VEHICLE_SCALES: dict[str, tuple[str, tuple[str, ...]]] = {
    "mass_scale": ("body", ("mass_kg",)),
    "inertia_scale": ("body", ("inertia_kgm2",)),
    "thrust_coefficient_scale": ("propulsion", ("thrust_coefficient_n_per_radps2",)),
    "torque_coefficient_scale": ("propulsion", ("torque_coefficient_nm_per_radps2",)),
    "motor_time_constant_scale": ("propulsion", ("motor_time_constant_s",)),
    "imu_noise_scale": (
        "imu",
        ("gyro_noise_density_radps_per_sqrthz", "accel_noise_density_mps2_per_sqrthz"),
    ),
}
NO_FAULT = "none"


class CampaignError(RigError):
    """A campaign file that cannot be run, or a results folder that cannot be used."""


@dataclass(frozen=True)
class Criterion:
    """One pass criterion: the metric must be within ``[min, max]`` (or equal ``equals``)."""

    metric: str
    minimum: float | None = None
    maximum: float | None = None
    equals: bool | None = None

    def violation(self, value: float | bool | None) -> str | None:
        """Why ``value`` fails this criterion, or None. A missing value (no failsafe, say)
        fails a bound: the criterion asked for it."""
        if self.equals is not None:
            return None if value == self.equals else f"{self.metric} = {value} != {self.equals}"
        if value is None:
            return f"{self.metric} not measured (none in the run)"
        if self.minimum is not None and value < self.minimum:
            return f"{self.metric} = {value:.3g} < {self.minimum:g}"
        if self.maximum is not None and value > self.maximum:
            return f"{self.metric} = {value:.3g} > {self.maximum:g}"
        return None


@table
class CrashLimits:
    """When the vehicle counts as crashed: tilted past the limit, or hit the ground harder."""

    tilt_deg: Positive = 60.0
    impact_speed_mps: Positive = 2.0


@dataclass(frozen=True)
class CredibilityScoring:
    """Score every case with a credibility plan: the case's ``log`` (``rig.ulg`` or
    ``autopilot.ulg``) fills the plan's ``role``; the other roles keep the plan's paths.
    ``plan_sha256`` is the plan file's hash, kept with the results for provenance."""

    plan_path: str
    plan_sha256: str
    role: str = "sim"
    log: str = "autopilot"


# -- the campaign file's tables (hil_config) ----------------------------------------------

Assignment = Annotated[str, Field(strict=True, pattern=r"^[A-Za-z0-9_]+=.+$")]
Values = Annotated[tuple[T, ...], Field(min_length=1)]


@table
class Axes:
    """The axes to sweep, each a non-empty list; the cases are their Cartesian product in
    the file's order. ``fault`` names ``[faults.NAME]`` tables (or ``"none"``); a
    ``*_scale`` multiplies the vehicle-file entries of :data:`VEHICLE_SCALES`."""

    fault: Values[Text] | None = None
    fault_onset_s: Values[NonNegative] | None = None
    wind_north_mps: Values[Number] | None = None
    wind_east_mps: Values[Number] | None = None
    seed: Values[NonNegativeInteger] | None = None
    autopilot_params: Values[tuple[Assignment, ...]] | None = None
    mass_scale: Values[Positive] | None = None
    inertia_scale: Values[Positive] | None = None
    thrust_coefficient_scale: Values[Positive] | None = None
    torque_coefficient_scale: Values[Positive] | None = None
    motor_time_constant_scale: Values[Positive] | None = None
    imu_noise_scale: Values[Positive] | None = None


@table
class FaultSweep:
    """What a ``[faults.NAME]`` table adds to a scenario fault (whose start is the onset)."""

    #: The parameter whose list of values is swept, one case per value.
    severity: Text | None = None
    #: The fault's length; None: until the end of the run.
    duration_s: Positive | None = None


@table
class Bounds:
    """A pass criterion on one metric: ``min`` and/or ``max``, or ``equals`` for ``crashed``."""

    min: Number | None = None
    max: Number | None = None
    equals: Annotated[bool, Field(strict=True)] | None = None


@table
class CredibilityTable:
    """``[credibility]``: the plan scoring every case (a path relative to the campaign file,
    or a bundled plan's name), the plan role the case's log fills, and which log."""

    plan: Text
    role: Text = "sim"
    log: Literal[CASE_LOGS] = "autopilot"


@table
class CampaignFile:
    name: Text
    scenario: Text
    description: str = ""
    #: None: the base scenario's.
    duration_s: Positive | None = None
    sensor_layer: SensorLayer = SensorLayer.TLM
    #: Wall time before a case counts as hung.
    case_timeout_s: Positive = 600.0
    #: Wall time for one autopilot answer before it counts as stalled.
    answer_timeout_s: Positive = 10.0
    first_instance: NonNegativeInteger = 20
    instances: PositiveInteger = 40
    axes: Axes = Axes()
    #: ``[faults.NAME]``: a scenario fault without its start; ``severity`` names the
    #: parameter whose list of values is swept, ``duration_s`` the fault's length.
    faults: dict[str, dict[str, Any]] = field(default_factory=dict)
    criteria: dict[Literal[METRICS], Bounds] = field(default_factory=dict)
    crash: CrashLimits = CrashLimits()
    credibility: CredibilityTable | None = None

    def __post_init__(self) -> None:
        if self.first_instance + self.instances > 100:
            raise FieldError(
                "instances", self.instances,
                f"first_instance ({self.first_instance}) + instances must lie within SITL "
                "instances 0..99",
            )  # fmt: skip
        for metric, bounds in self.criteria.items():
            given = {k: v for k, v in asdict(bounds).items() if v is not None}
            if metric == "crashed" and set(given) != {"equals"}:
                raise FieldError(f"criteria.{metric}", given, "expected {equals = true|false}")
            if metric != "crashed" and ("equals" in given or not given):
                raise FieldError(f"criteria.{metric}", given, "expected min and/or max")
            if metric in CREDIBILITY_METRICS and self.credibility is None:
                raise FieldError(f"criteria.{metric}", given, "needs a [credibility] table")
        if NO_FAULT in self.faults:
            raise FieldError(f"faults.{NO_FAULT}", NO_FAULT, "is the no-fault case, not a name")
        for name in self.axes.fault or ():
            if name != NO_FAULT and name not in self.faults:
                raise FieldError("axes.fault", name, f"no [faults.{name}] table")


@dataclass(frozen=True)
class Campaign:
    """A checked campaign file: its settings, the axes in file order, the faults by name."""

    file: CampaignFile
    source: str
    axes: tuple[tuple[str, tuple[Any, ...]], ...]
    criteria: tuple[Criterion, ...]
    credibility: CredibilityScoring | None = None


@dataclass(frozen=True)
class CaseSpec:
    """Everything one case needs, picklable for a process pool or a Dask worker."""

    case_id: str
    index: int
    labels: tuple[tuple[str, str], ...]  # axis → value as shown in the report
    scenario_document: Mapping[str, Any]
    vehicle_document: Mapping[str, Any]
    autopilot_params: tuple[str, ...]
    onset_s: float | None
    run_dir: str
    sensor_layer: str
    timeout_s: float
    answer_timeout_s: float
    first_instance: int
    instances: int
    crash: CrashLimits
    criteria: tuple[Criterion, ...]
    credibility: CredibilityScoring | None = None


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


# -- the campaign file -------------------------------------------------------------------


def load_campaign(name_or_path: str | Path) -> Campaign:
    """Load a bundled campaign by name or any campaign file; one-line :class:`CampaignError`."""
    document, path = read_toml(name_or_path, CAMPAIGNS_DIR, kind="campaign", error=CampaignError)
    return campaign_from_dict(document, str(path))


def campaign_from_dict(document: Mapping[str, Any], source: str = "<dict>") -> Campaign:
    """Check a parsed campaign document; the base scenario and every case are checked too."""
    file = parse(CampaignFile, document, source, CampaignError)
    for name, fault in file.faults.items():
        sweep = {key: fault[key] for key in ("severity", "duration_s") if key in fault}
        severity = parse(FaultSweep, sweep, f"{source}: faults.{name}", CampaignError).severity
        values = fault.get(severity)
        if severity is not None and (not isinstance(values, list) or not values):
            raise CampaignError(
                f"{source}: key 'faults.{name}.severity' = {severity!r}: expected a parameter "
                f"of {fault.get('kind')} whose value is a list of severities"
            )
        for variant in _fault_variants(name, file.faults):
            parse(FaultSpec, _fault_table(fault, variant, 0.0), f"{source}: faults.{name}",
                  CampaignError)  # fmt: skip
    axes = tuple(
        (name, tuple(_values(name, file)))
        for name in document.get("axes", {})  # the file's order is the cases' order
    )
    criteria = tuple(
        Criterion(metric, minimum=bounds.min, maximum=bounds.max, equals=bounds.equals)
        for metric, bounds in file.criteria.items()
    )
    scoring = None if file.credibility is None else _credibility(file.credibility, source)
    campaign = Campaign(file, source, axes, criteria, scoring)
    expand(campaign, Path("."))  # every case must make a valid scenario and vehicle
    return campaign


def _values(axis: str, file: CampaignFile) -> list[Any]:
    """An axis's values; a fault with a severity list becomes one value per severity."""
    values = getattr(file.axes, axis)
    if axis == "fault":
        return [variant for name in values for variant in _fault_variants(name, file.faults)]
    if axis == "autopilot_params":
        return [list(assignments) for assignments in values]
    return list(values)


def _credibility(table: CredibilityTable, source: str) -> CredibilityScoring:
    """The plan is loaded and checked here, once, so a bad plan or role stops the campaign
    before any case flies."""

    def fail(key: str, value: Any, reason: str) -> CampaignError:
        return CampaignError(f"{source}: key {key!r} = {value!r}: {reason}")

    path = _plan_path(table.plan, Path(source).parent)
    if path is None:
        bundled = ", ".join(sorted(p.stem for p in PLANS_DIR.glob("*.toml")))
        raise fail("credibility.plan", table.plan, f"no such plan file (bundled: {bundled})")
    try:
        plan = load_plan(path)
    except CredibilityError as error:
        raise fail("credibility.plan", table.plan, str(error)) from None
    if table.role not in plan.logs:
        raise fail(
            "credibility.role", table.role, f"not a log role of the plan ({', '.join(plan.logs)})"
        )
    return CredibilityScoring(
        plan_path=str(path),
        plan_sha256=hashlib.sha256(path.read_bytes()).hexdigest(),
        role=table.role,
        log=table.log,
    )


def _plan_path(name: str, campaign_dir: Path) -> Path | None:
    """A plan file relative to the campaign file, else a bundled plan by name."""
    for candidate in (campaign_dir / name, PLANS_DIR / name, PLANS_DIR / f"{name}.toml"):
        if candidate.is_file():
            return candidate.resolve()
    return None


def _fault_variants(name: str, faults: Mapping[str, Any]) -> list[tuple[str, str | None, Any]]:
    """``(name, swept parameter, severity)`` for each severity of a fault."""
    severity = None if name == NO_FAULT else faults[name].get("severity")
    if severity is None:
        return [(name, None, None)]
    return [(name, severity, value) for value in faults[name][severity]]


def _fault_table(
    fault: Mapping[str, Any], variant: tuple[str, str | None, Any], start_s: float
) -> dict[str, Any]:
    """The scenario's ``[[faults]]`` entry of one fault variant starting at ``start_s``."""
    _, parameter, severity = variant
    table = {k: v for k, v in fault.items() if k not in ("severity", "duration_s")}
    table.update(start_s=start_s, **({} if parameter is None else {parameter: severity}))
    if "duration_s" in fault:
        table["end_s"] = start_s + fault["duration_s"]
    return table


# -- cases -------------------------------------------------------------------------------


def expand(campaign: Campaign, out_dir: Path) -> list[CaseSpec]:
    """The Cartesian product of the axes, in file order; each case checked as a scenario."""
    settings = campaign.file
    base, base_path = read_toml(
        settings.scenario, SCENARIOS_DIR, kind="scenario", error=CampaignError
    )
    vehicle_name = base.get("vehicle")
    try:
        vehicle, _ = read_toml(vehicle_name, VEHICLES_DIR, kind="vehicle", error=VehicleFileError)
    except (VehicleFileError, TypeError) as error:
        raise CampaignError(f"{base_path}: key 'vehicle': {error}") from None
    names = [name for name, _ in campaign.axes]
    cases = []
    for index, values in enumerate(itertools.product(*(v for _, v in campaign.axes))):
        chosen = dict(zip(names, values, strict=True))
        scenario = copy.deepcopy(base)
        vehicle_doc = copy.deepcopy(vehicle)
        if settings.duration_s is not None:  # a shorter run drops what would come after it
            scenario["duration_s"] = settings.duration_s
            for key, time_key in (("commands", "at_s"), ("faults", "start_s")):
                if key in scenario:
                    scenario[key] = [item for item in scenario[key]
                                     if item.get(time_key, 0.0) < settings.duration_s]  # fmt: skip
        scenario["sensor_layer"] = str(settings.sensor_layer)
        onset_s = _apply(chosen, campaign, scenario, vehicle_doc)
        labels = tuple((name, _label(name, value)) for name, value in chosen.items())
        # Everything the case flies, and its labels (the onset also sets the metric window
        # of a no-fault case): a rerun of the same file finds the same ids.
        flown = [labels, scenario, vehicle_doc, chosen.get("autopilot_params", [])]
        case_id = hashlib.sha256(json.dumps(flown, sort_keys=True).encode()).hexdigest()[:12]
        scenario["vehicle"] = "vehicle.toml"  # run_case writes it beside scenario.toml
        source = f"{campaign.source}: case {index} ({', '.join(f'{k}={v}' for k, v in labels)})"
        try:
            vehicle_from_dict(vehicle_doc, f"{source}: vehicle")
        except VehicleFileError as error:
            raise CampaignError(str(error)) from None
        scenario_from_dict(scenario, source)  # raises ScenarioError naming the case
        cases.append(
            CaseSpec(
                case_id=case_id,
                index=index,
                labels=labels,
                scenario_document=scenario,
                vehicle_document=vehicle_doc,
                autopilot_params=tuple(chosen.get("autopilot_params", ())),
                onset_s=onset_s,
                run_dir=str(out_dir / f"case-{index:04d}-{case_id}"),
                sensor_layer=settings.sensor_layer,
                timeout_s=settings.case_timeout_s,
                answer_timeout_s=settings.answer_timeout_s,
                first_instance=settings.first_instance,
                instances=settings.instances,
                crash=settings.crash,
                criteria=campaign.criteria,
                credibility=campaign.credibility,
            )
        )
    return cases


def _apply(chosen: Mapping[str, Any], campaign: Campaign, scenario: dict, vehicle: dict):
    """Write the chosen axis values into the scenario and vehicle documents; returns the
    fault onset (the start of the window the metrics look at) or None."""
    onset_s = chosen.get("fault_onset_s")
    if "seed" in chosen:
        scenario["seed"] = chosen["seed"]
    if "wind_north_mps" in chosen or "wind_east_mps" in chosen:
        wind = scenario.setdefault("environment", {}).setdefault("wind", {})
        down = wind.get("steady_ned_mps", [0.0, 0.0, 0.0])[2]
        wind["steady_ned_mps"] = [
            float(chosen.get("wind_north_mps", 0.0)),
            float(chosen.get("wind_east_mps", 0.0)),
            down,
        ]
    for axis, (section, keys) in VEHICLE_SCALES.items():
        if axis in chosen:
            for key in keys:
                vehicle[section][key] = _scaled(vehicle[section][key], chosen[axis])
    variant = chosen.get("fault", (NO_FAULT, None, None))
    if variant[0] != NO_FAULT:
        start_s = 0.0 if onset_s is None else float(onset_s)
        fault = _fault_table(campaign.file.faults[variant[0]], variant, start_s)
        scenario["faults"] = [*scenario.get("faults", []), fault]
    return None if onset_s is None else float(onset_s)


def _scaled(value: Any, factor: float) -> Any:
    if isinstance(value, list):
        return [_scaled(v, factor) for v in value]
    return value * factor


def _label(axis: str, value: Any) -> str:
    if axis == "fault":
        name, parameter, severity = value
        return name if parameter is None else f"{name} {parameter}={severity}"
    if axis == "autopilot_params":
        return " ".join(value) or "defaults"
    return f"{value:g}" if isinstance(value, float) else str(value)


# -- running -----------------------------------------------------------------------------


def run_case(spec: CaseSpec) -> CaseResult:
    """Run one case in its own process under the wall-clock timeout; never raises for a
    failure of the run itself (that is the case's result)."""
    run_dir = Path(spec.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "outcome.json").unlink(missing_ok=True)  # from an interrupted earlier attempt
    vehicle_path = (run_dir / "vehicle.toml").resolve()
    scenario = {**spec.scenario_document, "vehicle": str(vehicle_path)}
    (run_dir / "scenario.toml").write_text(tomli_w.dumps(scenario))
    (run_dir / "vehicle.toml").write_text(tomli_w.dumps(spec.vehicle_document))
    (run_dir / "case.json").write_text(json.dumps(asdict(spec), indent=1, default=str))
    started = time.monotonic()
    with open(run_dir / "case.log", "wb") as output:
        process = subprocess.Popen(
            [sys.executable, "-m", "rig.apps.campaign_case", str(run_dir)],
            stdout=output,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            preexec_fn=restore_sigint,
        )
        try:
            process.wait(timeout=spec.timeout_s)
            hung = False
        except subprocess.TimeoutExpired:
            hung = True
            stop_process_group(process, STOP_GRACE_S)
        except BaseException:  # Ctrl-C or a cancelled worker: never leave the case running
            stop_process_group(process, STOP_GRACE_S)
            raise
    wall_s = time.monotonic() - started
    outcome = _read_outcome(run_dir)
    metrics = outcome.get("metrics", {}) if outcome else {}
    if hung:
        status, reason = "hung", f"no result after {spec.timeout_s:g} s wall time (stopped)"
    elif outcome is None:
        status, reason = (
            "crashed",
            f"case process exit code {process.returncode}: " + _tail(run_dir / "case.log"),
        )
    elif outcome["error"]:
        status, reason = "crashed", outcome["error"]
    else:
        violations = [v for c in spec.criteria if (v := c.violation(metrics.get(c.metric)))]
        # Notes (e.g. why a credibility index is missing) come with the reason either way.
        status = "failed" if violations else "ok"
        reason = "; ".join([*violations, *outcome.get("notes", [])])
    logs = {
        name: str(run_dir / f"{name}.ulg")
        for name in CASE_LOGS
        if (run_dir / f"{name}.ulg").is_file()
    }
    return CaseResult(
        case_id=spec.case_id,
        index=spec.index,
        labels=spec.labels,
        status=status,
        reason=reason,
        metrics=metrics,
        wall_s=wall_s,
        run_dir=spec.run_dir,
        rig_log=logs.get("rig"),
        autopilot_log=logs.get("autopilot"),
    )


def _read_outcome(run_dir: Path) -> dict[str, Any] | None:
    try:
        return json.loads((run_dir / "outcome.json").read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None


def _tail(path: Path) -> str:
    lines = [line for line in path.read_text(errors="replace").splitlines() if line.strip()]
    return lines[-1].strip() if lines else "no output"


def run_campaign(
    campaign: Campaign,
    out_dir: Path,
    executor: Executor,
    on_result: Callable[[CaseResult], None] | None = None,
) -> list[CaseResult]:
    """Run the cases not yet in ``out_dir/results.sqlite``; returns the new results.

    Each result is committed as it arrives; on Ctrl-C the queued cases are cancelled and
    the running ones stopped by their workers, and every committed row stays."""
    out_dir.mkdir(parents=True, exist_ok=True)
    cases = expand(campaign, out_dir)
    with ResultsDb(out_dir / RESULTS_DB) as db:
        if campaign.credibility is not None:
            db.record_plan(campaign.credibility)
        done = db.finished_ids()
        futures: list[Future[CaseResult]] = [
            executor.submit(run_case, case) for case in cases if case.case_id not in done
        ]
        results = []
        try:
            for future in as_completed(futures):
                result = future.result()
                db.record(result)
                results.append(result)
                if on_result is not None:
                    on_result(result)
        finally:
            for future in futures:
                future.cancel()
    return results


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
                *row[:2], tuple(json.loads(row[2]).items()), *row[3:5], json.loads(row[5]), *row[6:]
            )
            for row in rows
        ]


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


@contextlib.contextmanager
def campaign_executor(
    scheduler: str | None = None, workers: int | None = None
) -> Iterator[Executor]:
    """A local process pool of ``workers`` (default: the cores this process may use), or
    the Dask cluster at ``scheduler`` (``tcp://HOST:8786``) through its executor."""
    if scheduler is None:
        with ProcessPoolExecutor(max_workers=workers or len(os.sched_getaffinity(0))) as pool:
            yield pool
        return
    from dask.distributed import Client  # imported on demand: Dask is slow to import

    try:
        client = Client(scheduler, timeout="20s")
    except OSError as error:
        raise CampaignError(
            f"--scheduler {scheduler}: cannot reach the Dask scheduler ({error})"
        ) from None
    with client, client.get_executor(pure=False) as executor:
        yield executor
