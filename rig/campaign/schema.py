"""A campaign file's tables, checked as they are read, and the campaign they describe."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar, get_args

from pydantic import Field

from hil_config import (
    FieldError,
    NonNegative,
    NonNegativeInteger,
    Number,
    Positive,
    PositiveInteger,
    Text,
    table,
)
from rig.errors import RigError
from rig.scenarios.scenario import SensorLayer

T = TypeVar("T")


CAMPAIGNS_DIR = Path(__file__).parent / "campaigns"


PLANS_DIR = Path(__file__).parents[2] / "credibility" / "plans"


#: A metric each case reports (rig.campaign.case computes them from the run's logs).
Metric = Literal[
    "max_tilt_deg",
    "altitude_loss_m",
    "time_to_failsafe_s",
    "impact_speed_mps",
    "crashed",
    "eta_all",
    "eta_min",
]
#: The metrics in report order.
METRICS: tuple[Metric, ...] = get_args(Metric)


#: The metrics only a campaign with a ``[credibility]`` table measures.
CREDIBILITY_METRICS = ("eta_all", "eta_min")


#: Which of a case's logs can fill the credibility plan's role.
CaseLog = Literal["rig", "autopilot"]
CASE_LOGS: tuple[CaseLog, ...] = get_args(CaseLog)


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
    log: CaseLog = "autopilot"


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
    criteria: dict[Metric, Bounds] = field(default_factory=dict)
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


def fault_variants(name: str, faults: Mapping[str, Any]) -> list[tuple[str, str | None, Any]]:
    """``(name, swept parameter, severity)`` for each severity of a fault."""
    severity = None if name == NO_FAULT else faults[name].get("severity")
    if severity is None:
        return [(name, None, None)]
    return [(name, severity, value) for value in faults[name][severity]]


def fault_table(
    fault: Mapping[str, Any], variant: tuple[str, str | None, Any], start_s: float
) -> dict[str, Any]:
    """The scenario's ``[[faults]]`` entry of one fault variant starting at ``start_s``."""
    _, parameter, severity = variant
    table = {k: v for k, v in fault.items() if k not in ("severity", "duration_s")}
    table.update(start_s=start_s, **({} if parameter is None else {parameter: severity}))
    if "duration_s" in fault:
        table["end_s"] = start_s + fault["duration_s"]
    return table
