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
from collections.abc import Callable, Iterable, Iterator, Mapping
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import tomli_w

from credibility import CredibilityError, load_plan
from quad_model.toml_file import read_toml_file
from quad_model.vehicle import VEHICLES_DIR, VehicleFileError, vehicle_from_dict
from rig.errors import RigError
from rig.processes import stop_process_group
from rig.scenarios.scenario import FAULT_KINDS, SCENARIOS_DIR, SENSOR_LAYERS, scenario_from_dict

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
#: Every axis a campaign may sweep, with the kind of its values.
AXES = {
    "fault": "fault name",
    "fault_onset_s": "non-negative number",
    "wind_north_mps": "number",
    "wind_east_mps": "number",
    "seed": "integer >= 0",
    "autopilot_params": "list of NAME=VALUE strings",
    **dict.fromkeys(VEHICLE_SCALES, "positive number"),
}
NO_FAULT = "none"
_TOP_KEYS = {
    "name",
    "description",
    "scenario",
    "duration_s",
    "sensor_layer",
    "case_timeout_s",
    "answer_timeout_s",
    "first_instance",
    "instances",
    "axes",
    "faults",
    "criteria",
    "crash",
    "credibility",
}
_CREDIBILITY_KEYS = ("plan", "role", "log")


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


@dataclass(frozen=True)
class CrashLimits:
    """When the vehicle counts as crashed: tilted past the limit, or hit the ground harder."""

    tilt_deg: float = 60.0
    impact_speed_mps: float = 2.0


@dataclass(frozen=True)
class CredibilityScoring:
    """Score every case with a credibility plan: the case's ``log`` (``rig.ulg`` or
    ``autopilot.ulg``) fills the plan's ``role``; the other roles keep the plan's paths.
    ``plan_sha256`` is the plan file's hash, kept with the results for provenance."""

    plan_path: str
    plan_sha256: str
    role: str = "sim"
    log: str = "autopilot"


@dataclass(frozen=True)
class Campaign:
    name: str
    source: str
    description: str
    scenario: str
    duration_s: float | None  # None: the base scenario's
    sensor_layer: str
    case_timeout_s: float
    answer_timeout_s: float
    first_instance: int
    instances: int
    axes: tuple[tuple[str, tuple[Any, ...]], ...]
    faults: Mapping[str, Mapping[str, Any]]
    criteria: tuple[Criterion, ...]
    crash: CrashLimits
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
    document, path = read_toml_file(
        name_or_path, CAMPAIGNS_DIR, kind="campaign", error=CampaignError
    )
    return campaign_from_dict(document, str(path))


def campaign_from_dict(document: Mapping[str, Any], source: str = "<dict>") -> Campaign:
    """Check a parsed campaign document; the base scenario and every case are checked too."""

    def fail(key: str, value: Any, reason: str) -> CampaignError:
        return CampaignError(f"{source}: key {key!r} = {value!r}: {reason}")

    for key in document:
        if key not in _TOP_KEYS:
            raise fail(key, document[key], f"unknown key (known: {', '.join(sorted(_TOP_KEYS))})")
    for key in ("name", "scenario"):
        if not isinstance(document.get(key), str) or not document[key]:
            raise CampaignError(f"{source}: key {key!r} is missing or not a string")

    def number(key: str, default: float | None, minimum: float = 0.0) -> float | None:
        value = document.get(key, default)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float) or value <= minimum:
            raise fail(key, value, f"expected a number > {minimum:g}")
        return float(value)

    sensor_layer = document.get("sensor_layer", "tlm")
    if sensor_layer not in SENSOR_LAYERS:
        raise fail("sensor_layer", sensor_layer, f"expected one of {', '.join(SENSOR_LAYERS)}")
    first_instance = document.get("first_instance", 20)
    instances = document.get("instances", 40)
    if not (
        isinstance(first_instance, int)
        and isinstance(instances, int)
        and first_instance >= 0
        and instances > 0
        and first_instance + instances <= 100
    ):
        raise fail(
            "instances",
            [first_instance, instances],
            "first_instance + instances must lie within SITL instances 0..99",
        )
    faults = _faults(document.get("faults", {}), fail)
    axes = _axes(document.get("axes", {}), faults, fail)
    crash_table = document.get("crash", {})
    crash = CrashLimits(
        **{
            k: float(v)
            for k, v in _table(crash_table, "crash", fail).items()
            if _known(k, CrashLimits.__dataclass_fields__, "crash", v, fail)
        }
    )
    campaign = Campaign(
        name=document["name"],
        source=source,
        description=str(document.get("description", "")),
        scenario=document["scenario"],
        duration_s=number("duration_s", None),
        sensor_layer=sensor_layer,
        case_timeout_s=number("case_timeout_s", 600.0),
        answer_timeout_s=number("answer_timeout_s", 10.0),
        first_instance=first_instance,
        instances=instances,
        axes=axes,
        faults=faults,
        criteria=_criteria(document.get("criteria", {}), fail),
        crash=crash,
        credibility=_credibility(document.get("credibility"), source, fail),
    )
    for criterion in campaign.criteria:
        if criterion.metric in CREDIBILITY_METRICS and campaign.credibility is None:
            raise fail(
                f"criteria.{criterion.metric}",
                document["criteria"][criterion.metric],
                "needs a [credibility] table",
            )
    expand(campaign, Path("."))  # every case must make a valid scenario and vehicle
    return campaign


def _credibility(
    table: Any, source: str, fail: Callable[..., CampaignError]
) -> CredibilityScoring | None:
    """``[credibility]``: the plan is loaded and checked here, once, so a bad plan or role
    stops the campaign before any case flies."""
    if table is None:
        return None
    table = _table(table, "credibility", fail)
    for key, value in table.items():
        _known(key, _CREDIBILITY_KEYS, "credibility", value, fail)
    name = table.get("plan")
    if not isinstance(name, str) or not name:
        raise fail("credibility.plan", name, "expected a plan file or a bundled plan name")
    path = _plan_path(name, Path(source).parent)
    if path is None:
        bundled = ", ".join(sorted(p.stem for p in PLANS_DIR.glob("*.toml")))
        raise fail("credibility.plan", name, f"no such plan file (bundled: {bundled})")
    try:
        plan = load_plan(path)
    except CredibilityError as error:
        raise fail("credibility.plan", name, str(error)) from None
    role = table.get("role", "sim")
    if role not in plan.logs:
        raise fail("credibility.role", role, f"not a log role of the plan ({', '.join(plan.logs)})")
    log = table.get("log", "autopilot")
    if log not in CASE_LOGS:
        raise fail("credibility.log", log, f"expected one of {', '.join(CASE_LOGS)}")
    return CredibilityScoring(
        plan_path=str(path),
        plan_sha256=hashlib.sha256(path.read_bytes()).hexdigest(),
        role=role,
        log=log,
    )


def _plan_path(name: str, campaign_dir: Path) -> Path | None:
    """A plan file relative to the campaign file, else a bundled plan by name."""
    for candidate in (campaign_dir / name, PLANS_DIR / name, PLANS_DIR / f"{name}.toml"):
        if candidate.is_file():
            return candidate.resolve()
    return None


def _table(value: Any, key: str, fail: Callable[..., CampaignError]) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise fail(key, value, "expected a table")
    return value


def _known(
    key: str, known: Iterable[str], prefix: str, value: Any, fail: Callable[..., CampaignError]
) -> bool:
    if key not in known:
        raise fail(f"{prefix}.{key}", value, f"unknown key (known: {', '.join(sorted(known))})")
    return True


def _faults(table: Any, fail: Callable[..., CampaignError]) -> dict[str, dict[str, Any]]:
    """``[faults.NAME]``: a scenario fault without its start; ``severity`` names the
    parameter whose list of values is swept, ``duration_s`` (optional) the fault's length."""
    faults = {}
    for name, fault in _table(table, "faults", fail).items():
        fault = dict(_table(fault, f"faults.{name}", fail))
        kind = fault.get("kind")
        if kind not in FAULT_KINDS:
            raise fail(f"faults.{name}.kind", kind, f"expected one of {', '.join(FAULT_KINDS)}")
        for key, value in fault.items():
            _known(
                key,
                {"kind", "duration_s", "severity", *FAULT_KINDS[kind]},
                f"faults.{name}",
                value,
                fail,
            )
        severity = fault.get("severity")
        if severity is not None and (
            severity not in FAULT_KINDS[kind]
            or not isinstance(fault.get(severity), list)
            or not fault[severity]
        ):
            raise fail(
                f"faults.{name}.severity",
                severity,
                f"expected a parameter of {kind} whose value is a list of severities",
            )
        if name == NO_FAULT:
            raise fail(f"faults.{name}", name, f"{NO_FAULT!r} is the no-fault case, not a name")
        faults[name] = fault
    return faults


def _axes(
    table: Any, faults: Mapping[str, Any], fail: Callable[..., CampaignError]
) -> tuple[tuple[str, tuple[Any, ...]], ...]:
    axes = []
    for name, values in _table(table, "axes", fail).items():
        _known(name, AXES, "axes", values, fail)
        if not isinstance(values, list) or not values:
            raise fail(f"axes.{name}", values, "expected a non-empty list")
        for value in values:
            if not _axis_value_ok(name, value, faults):
                raise fail(f"axes.{name}", value, f"expected a {AXES[name]}")
        if name == "fault":  # a fault with a severity list becomes one value per severity
            values = [v for name_ in values for v in _fault_variants(name_, faults)]
        axes.append((name, tuple(values)))
    return tuple(axes)


def _axis_value_ok(axis: str, value: Any, faults: Mapping[str, Any]) -> bool:
    is_number = isinstance(value, int | float) and not isinstance(value, bool)
    if axis == "fault":
        return value == NO_FAULT or value in faults
    if axis == "seed":
        return isinstance(value, int) and not isinstance(value, bool) and value >= 0
    if axis == "autopilot_params":
        return isinstance(value, list) and all(isinstance(v, str) and "=" in v for v in value)
    if axis == "fault_onset_s":
        return is_number and value >= 0
    if axis in VEHICLE_SCALES:
        return is_number and value > 0
    return is_number


def _fault_variants(name: str, faults: Mapping[str, Any]) -> list[tuple[str, str | None, Any]]:
    """``(name, swept parameter, severity)`` for each severity of a fault."""
    severity = None if name == NO_FAULT else faults[name].get("severity")
    if severity is None:
        return [(name, None, None)]
    return [(name, severity, value) for value in faults[name][severity]]


def _criteria(table: Any, fail: Callable[..., CampaignError]) -> tuple[Criterion, ...]:
    criteria = []
    for metric, bound in _table(table, "criteria", fail).items():
        _known(metric, METRICS, "criteria", bound, fail)
        bound = _table(bound, f"criteria.{metric}", fail)
        for key, value in bound.items():
            _known(key, ("min", "max", "equals"), f"criteria.{metric}", value, fail)
        if metric == "crashed":
            if set(bound) != {"equals"} or not isinstance(bound["equals"], bool):
                raise fail("criteria.crashed", dict(bound), "expected {equals = true|false}")
            criteria.append(Criterion(metric, equals=bound["equals"]))
            continue
        if "equals" in bound or not bound:
            raise fail(f"criteria.{metric}", dict(bound), "expected min and/or max")
        for key in bound:
            if isinstance(bound[key], bool) or not isinstance(bound[key], int | float):
                raise fail(f"criteria.{metric}.{key}", bound[key], "expected a number")
        criteria.append(Criterion(metric, minimum=bound.get("min"), maximum=bound.get("max")))
    return tuple(criteria)


# -- cases -------------------------------------------------------------------------------


def expand(campaign: Campaign, out_dir: Path) -> list[CaseSpec]:
    """The Cartesian product of the axes, in file order; each case checked as a scenario."""
    base, base_path = read_toml_file(
        campaign.scenario, SCENARIOS_DIR, kind="scenario", error=CampaignError
    )
    vehicle_name = base.get("vehicle")
    try:
        vehicle, _ = read_toml_file(
            vehicle_name, VEHICLES_DIR, kind="vehicle", error=VehicleFileError
        )
    except (VehicleFileError, TypeError) as error:
        raise CampaignError(f"{base_path}: key 'vehicle': {error}") from None
    names = [name for name, _ in campaign.axes]
    cases = []
    for index, values in enumerate(itertools.product(*(v for _, v in campaign.axes))):
        chosen = dict(zip(names, values, strict=True))
        scenario = copy.deepcopy(base)
        vehicle_doc = copy.deepcopy(vehicle)
        if campaign.duration_s is not None:  # a shorter run drops what would come after it
            scenario["duration_s"] = campaign.duration_s
            for key, time_key in (("commands", "at_s"), ("faults", "start_s")):
                if key in scenario:
                    scenario[key] = [item for item in scenario[key]
                                     if item.get(time_key, 0.0) < campaign.duration_s]  # fmt: skip
        scenario["sensor_layer"] = campaign.sensor_layer
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
                sensor_layer=campaign.sensor_layer,
                timeout_s=campaign.case_timeout_s,
                answer_timeout_s=campaign.answer_timeout_s,
                first_instance=campaign.first_instance,
                instances=campaign.instances,
                crash=campaign.crash,
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
        environment = scenario.setdefault("environment", {})
        down = environment.get("wind_steady_ned_mps", [0.0, 0.0, 0.0])[2]
        environment["wind_steady_ned_mps"] = [
            float(chosen.get("wind_north_mps", 0.0)),
            float(chosen.get("wind_east_mps", 0.0)),
            down,
        ]
    for axis, (section, keys) in VEHICLE_SCALES.items():
        if axis in chosen:
            for key in keys:
                vehicle[section][key] = _scaled(vehicle[section][key], chosen[axis])
    name, parameter, severity = chosen.get("fault", (NO_FAULT, None, None))
    if name != NO_FAULT:
        fault = dict(campaign.faults[name])
        fault.pop("severity", None)
        start_s = 0.0 if onset_s is None else float(onset_s)
        duration_s = fault.pop("duration_s", None)
        fault.update(start_s=start_s, **({} if parameter is None else {parameter: severity}))
        if duration_s is not None:
            fault["end_s"] = start_s + duration_s
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
        for name in ("rig", "autopilot")
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
