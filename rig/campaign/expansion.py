"""A campaign file loaded and expanded into its cases: the Cartesian product of its axes,
each case's scenario and vehicle checked as it is made (:func:`load_campaign`, :func:`expand`)."""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from credibility import CredibilityError, load_plan
from hil_config import (
    parse,
    read_toml,
)
from quad_model.vehicle import VEHICLES_DIR, VehicleFileError, vehicle_from_dict
from rig.campaign.schema import (
    CAMPAIGNS_DIR,
    NO_FAULT,
    PLANS_DIR,
    VEHICLE_SCALES,
    Campaign,
    CampaignError,
    CampaignFile,
    CrashLimits,
    CredibilityScoring,
    CredibilityTable,
    Criterion,
    FaultSweep,
    fault_table,
    fault_variants,
)
from rig.scenarios.scenario import SCENARIOS_DIR, FaultSpec, scenario_from_dict


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
        if severity is not None:
            values = fault.get(severity)
            if not isinstance(values, list) or not values:
                raise CampaignError(
                    f"{source}: key 'faults.{name}.severity' = {severity!r}: expected a "
                    f"parameter of {fault.get('kind')} whose value is a list of severities"
                )
        for variant in fault_variants(name, file.faults):
            parse(FaultSpec, fault_table(fault, variant, 0.0), f"{source}: faults.{name}",
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
        return [variant for name in values for variant in fault_variants(name, file.faults)]
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


def expand(campaign: Campaign, out_dir: Path) -> list[CaseSpec]:
    """The Cartesian product of the axes, in file order; each case checked as a scenario."""
    settings = campaign.file
    base, base_path = read_toml(
        settings.scenario, SCENARIOS_DIR, kind="scenario", error=CampaignError
    )
    # Still unchecked TOML: a missing or non-text vehicle is the TypeError below.
    vehicle_name: Any = base.get("vehicle")
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


def _apply(
    chosen: Mapping[str, Any],
    campaign: Campaign,
    scenario: dict[str, Any],
    vehicle: dict[str, Any],
) -> float | None:
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
        fault = fault_table(campaign.file.faults[variant[0]], variant, start_s)
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
