"""A complete vehicle file from a flight log and the vehicle's mass (``rig vehicle LOG --mass
KG``): what the log holds, what :mod:`rig.identify` fits from it, and the generic multicopter
of that mass (:mod:`rig.identify.generic`) for the rest, every value tagged with its source
and its ± on its line.

Why a prior at all: the identification fits a vehicle's values against the model of one (the
hover speed curve keeps its full-throttle point, the vibration fit flies the model on its
thrust stand), and an airframe that is not bundled has none; the generic one of its mass
and rotor geometry stands in, and every value the log then gives replaces its own.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np

from px4_logs import FlightLog, LogError, motor_outputs
from quad_model.vehicle import Vehicle, vehicle_from_dict
from rig.identify.bounds import QUAD_ROTORS
from rig.identify.generic import frame_class, generic_vehicle
from rig.identify.report import format_estimate
from rig.identify.results import Estimate, Identification, IdentificationError
from rig.identify.vehicle import identify_vehicle
from rig.identify.vibration import FITTED_POINTS, fit_vibration, read_log_vibration, rest_point

#: The replay's IMU rate the vibration is fitted at (``rig identify --imu-hz``'s default).
IMU_RATE_HZ = 800.0
#: A value's source, as its line in the file says it.
TAGS = ("log", "identified", "default", "given")
#: The pack's identified values, each taken unless :mod:`rig.identify.bounds` refused it.
BATTERY_KEYS = (
    "battery.internal_resistance_ohm",
    "battery.propulsion_efficiency",
    "battery.avionics_power_w",
)

#: Above the armed idle's throttle where the ESCs do not start there (the 8S quad's 0.12).
ESC_START_MARGIN = 0.02

#: A smaller mean hub distance is no geometry (PX4's CA_ROTORn_PX/PY default to 0).
MIN_ARM_M = 1e-3
#: Why the rate plant's values are not taken without an excitation window.
UNCONFIRMED = (
    "rate plant not fitted: give --window START END of a manual excitation (over the whole "
    "flight its cross-check would be the same data)"
)

Source = tuple[str, str]  # (tag, why with its ±)


@dataclass(frozen=True)
class VehicleFromLog:
    """A vehicle and, per ``table.key``, its source tag and reasoning."""

    vehicle: Vehicle
    sources: dict[str, Source]
    header: tuple[str, ...]

    def toml(self) -> str:
        """The vehicle file's text. Written line by line: ``tomllib`` reads TOML but cannot
        write it, and every value needs its comment."""
        lines = [f"# {line}" for line in self.header]
        lines.append(f"name = {_toml_value(self.vehicle.name)}   {self._comment('name')}")
        for table in _tables(self.vehicle):
            lines += ["", f"[{table}]"]
            params = getattr(self.vehicle, table)
            for field in fields(params):
                value = _toml_value(getattr(params, field.name))
                lines.append(f"{field.name} = {value}   {self._comment(f'{table}.{field.name}')}")
        return "\n".join(lines) + "\n"

    def summary(self) -> list[str]:
        """One line per table: how many of its values have each source."""
        lines = []
        for table in _tables(self.vehicle):
            tags = [tag for key, (tag, _) in self.sources.items()
                    if key.split(".")[0] == table]  # fmt: skip
            counts = ", ".join(f"{tags.count(t)} [{t}]" for t in TAGS if tags.count(t))
            lines.append(f"[{table}] {counts}")
        return lines

    def _comment(self, key: str) -> str:
        tag, why = self.sources[key]
        return f"# [{tag}] {why}"


def vehicle_from_log(
    log: FlightLog,
    mass_kg: float,
    command: str,
    excitation_window_s: tuple[float, float] | None = None,
    imu_rate_hz: float = IMU_RATE_HZ,
) -> VehicleFromLog:
    """The vehicle of ``log`` weighing ``mass_kg``; ``command`` is named in the file's header.
    The inertia and motor lag are taken from the rate-loop fit only over an
    ``excitation_window_s``: without one the fit's whole-flight cross-check is the same data
    and confirms nothing. A log the identification does not handle (not 4 rotors), or
    without the parameters, is one line."""
    if not (math.isfinite(mass_kg) and mass_kg > 0):
        raise IdentificationError(f"--mass {mass_kg:g}: a mass is a positive number of kg")
    params, path = log.parameters, log.path
    count = int(_parameter(params, path, "CA_ROTOR_COUNT", "the rotor count"))
    if count != QUAD_ROTORS:
        raise IdentificationError(
            f"{path}: CA_ROTOR_COUNT = {count}: the identification handles {QUAD_ROTORS} rotors "
            "(a quad's hover and mixer); write another count's vehicle file by hand"
        )
    cells_name = next((n for n in ("BAT1_N_CELLS", "BAT_N_CELLS") if params.get(n, 0) >= 1), None)
    if cells_name is None:
        raise IdentificationError(
            f"{path}: parameter BAT1_N_CELLS (BAT_N_CELLS in older PX4) is not set in the log: "
            "the pack's cell count"
        )
    cells = int(params[cells_name])
    hubs, spins, metres = _rotors(params, path)
    arm = float(np.mean(np.hypot(*(hubs[:, :2] - hubs[:, :2].mean(axis=0)).T)))
    if arm < MIN_ARM_M:
        raise IdentificationError(f"{path}: parameters CA_ROTORn_PX/PY place every rotor at "
                                  "the centre: no rotor geometry")  # fmt: skip
    generic = generic_vehicle(mass_kg, cells, arm if metres else None)
    sources: dict[str, Source] = {key: ("default", why) for key, why in generic.notes.items()}
    prior = generic.vehicle
    if not metres:  # PX4's generic airframes give the unit square: its shape, the class's arm
        hubs[:, :2] *= frame_class(mass_kg)[1] / arm
    if not hubs[:, 2].any():  # PZ unset: the generic rotor plane
        hubs[:, 2] = prior.propulsion.position_frd_m[0][2]
    prior = replace(
        prior,
        propulsion=replace(
            prior.propulsion,
            position_frd_m=_rows(hubs),
            spin_direction=(spins[0], spins[1], spins[2], spins[3]),
        ),
    )
    result = identify_vehicle(log, prior, excitation_window_s)
    rate_plant = excitation_window_s is not None
    vehicle, identified = _identified(prior, result, hubs, metres, rate_plant, generic.notes)
    vehicle, fitted = _vibration(
        log,
        vehicle,
        result.hover.rotor_speed_radps,
        imu_rate_hz,
        generic.notes,
        _motor_outputs(log),
    )
    vehicle, logged = _logged(vehicle, params)
    sources |= identified | fitted | logged
    airframe = f"{int(params['SYS_AUTOSTART'])}" if "SYS_AUTOSTART" in params else "not logged"
    sources["name"] = ("log", f"SYS_AUTOSTART {airframe}, {path.name}")
    sources["body.mass_kg"] = ("given", "--mass: a log holds no weight")
    sources["battery.cell_count"] = ("log", f"{cells_name} = {cells}")
    vehicle = replace(vehicle, name=f"PX4 airframe {airframe} from {path.name}")
    header = (
        f"Vehicle file written by `{command}`",
        f"from {path.name}: {log.firmware}, airframe SYS_AUTOSTART {airframe}.",
        "Sources: [log] a parameter or a statistic of the log; [identified] fitted by rig "
        "identify (method, window, ±);",
        "[default] the generic multicopter of this mass (rig/identify/generic.py), ± how far "
        "the bundled vehicles lie from it;",
        "[given] the command line. ASSUMED marks what the log cannot tell.",
    )
    # through the schema: a value the model could not load never reaches the file
    checked = vehicle_from_dict(_document(vehicle), str(path))
    return VehicleFromLog(checked, sources, header)


def _parameter(params: Mapping[str, float], path: Path, name: str, what: str) -> float:
    if name not in params:
        raise IdentificationError(
            f"{path}: parameter {name} is not in the log ({what}; PX4 1.13+ control allocation)"
        )
    return float(params[name])


def _rotors(params: Mapping[str, float], path: Path) -> tuple[np.ndarray, list[int], bool]:
    """The hubs (CA_ROTORn_PX/PY/PZ; PZ 0 where not logged, as by the rig's own autopilot),
    the spin directions (CA_ROTORn_KM: PX4's allocator takes KM > 0 for a counter-clockwise
    rotor, as the model's +1), and whether the hubs are in metres: a largest |PX|, |PY| of
    exactly 1 is PX4's normalised square."""
    hubs = np.array([[_parameter(params, path, f"CA_ROTOR{i}_P{axis}", "rotor position")
                      for axis in "XY"] + [float(params.get(f"CA_ROTOR{i}_PZ", 0.0))]
                     for i in range(QUAD_ROTORS)])  # fmt: skip
    spins = []
    for i in range(QUAD_ROTORS):
        km = _parameter(params, path, f"CA_ROTOR{i}_KM", "rotor spin direction")
        if km == 0:
            raise IdentificationError(f"{path}: parameter CA_ROTOR{i}_KM = 0: no spin direction")
        spins.append(1 if km > 0 else -1)
    metres = not math.isclose(float(np.max(np.abs(hubs[:, :2]))), 1.0, abs_tol=1e-6)
    return hubs, spins, metres


def _identified(
    prior: Vehicle,
    result: Identification,
    hubs: np.ndarray,
    metres: bool,
    rate_plant: bool,
    defaults: Mapping[str, str],
) -> tuple[Vehicle, dict[str, Source]]:
    """``prior`` with what ``rig identify`` fitted (the rate plant's inertia and motor lag
    only if ``rate_plant``); a value outside what is physically possible is refused and the
    generic one (``defaults`` says how it was sized) kept, the line says why."""
    source = f"rig identify {result.log.name}"
    hover, prop, body, battery = result.hover, prior.propulsion, prior.body, prior.battery
    sources: dict[str, Source] = {}

    def keep(key: str, why: str) -> None:
        sources[key] = ("default", f"{defaults[key]}; {why}")

    centre = np.array([*hover.centre_of_mass_frd_m, 0.0])
    positions = hubs - np.append(hubs[:, :2].mean(axis=0), 0.0) - centre
    shape = ("CA_ROTORn_PX/PY/PZ (m)" if metres else "CA_ROTORn_PX/PY normalised (±1): their "
             "shape at the frame class's arm, ± 20 %")  # fmt: skip
    sources["propulsion.position_frd_m"] = (
        "log" if metres else "default",
        f"{shape}; less the centre of mass [identified] by the hover motors' balance, x "
        f"{centre[0] * 1e3:+.1f} mm, y {centre[1] * 1e3:+.1f} mm",
    )
    sources["propulsion.spin_direction"] = ("log", "CA_ROTORn_KM signs (> 0: CCW)")
    prop = replace(prop, position_frd_m=_rows(positions))
    throttle, offset, slope = hover.throttle, hover.speed_offset_radps, hover.speed_slope_radps
    refused = (
        throttle.refused or offset.refused or ("" if slope > 0 else f"slope {slope:.0f} rad/s")
    )
    if not refused:
        prop = replace(prop, speed_slope_radps=slope, speed_offset_radps=offset.value)
        sources["propulsion.speed_slope_radps"] = (
            "identified",
            f"{source}: through the hover, ω(1) = {slope + offset.value:.0f} rad/s [default] kept",
        )
        sources["propulsion.speed_offset_radps"] = (
            "identified",
            f"{source}: {format_estimate(offset)} rad/s, hover throttle "
            f"{format_estimate(throttle)} ({_window(offset)}); {offset.method}",
        )
    else:
        for key in ("propulsion.speed_slope_radps", "propulsion.speed_offset_radps"):
            keep(key, f"refused: {refused}")
    k_t = hover.thrust_coefficient
    if k_t is not None and not k_t.refused:
        prop = replace(prop, thrust_coefficient_n_per_radps2=k_t.value)
        sources["propulsion.thrust_coefficient_n_per_radps2"] = (
            "identified",
            f"{source}: ± {k_t.relative_uncertainty:.0%} ({_window(k_t)}); {k_t.method}",
        )
    else:
        reasons = (hover.measured_speed_reason, f"rotor line: {hover.rotor_line_reason}")
        why = k_t.refused if k_t is not None else "; ".join(r for r in reasons if r)
        keep("propulsion.thrust_coefficient_n_per_radps2", f"not identified: {why}")
    inertia = np.array(body.inertia_kgm2)
    axes = []
    for index, axis in enumerate(result.axes[:2]):
        estimate = axis.inertia_kgm2
        if rate_plant and axis.reliable and estimate is not None and not estimate.refused:
            inertia[index, index] = estimate.value
            axes.append(f"I_{'xyz'[index] * 2} {format_estimate(estimate)} ({_window(estimate)})")
    if axes:
        sources["body.inertia_kgm2"] = (
            "identified",
            f"{source}, rate plant: {'; '.join(axes)}; "
            f"the other axes {defaults['body.inertia_kgm2']}",
        )
        body = replace(body, inertia_kgm2=_rows(inertia))
    elif not rate_plant:
        keep("body.inertia_kgm2", UNCONFIRMED)
    else:
        keep("body.inertia_kgm2", f"not identified: {result.axes[0].reason.split(';')[0]}")
    lags = [a.motor_time_constant_s for a in result.axes
            if a.motor_lag_identified and a.motor_time_constant_s is not None
            and not a.motor_time_constant_s.refused]  # fmt: skip
    if rate_plant and lags:
        tau = float(np.mean([e.value for e in lags]))
        prop = replace(prop, motor_time_constant_s=tau)
        spread = max(e.uncertainty for e in lags)
        sources["propulsion.motor_time_constant_s"] = (
            "identified", f"{source}, rate plant, mean of {len(lags)} axes, ± {spread:.2g} s"
        )  # fmt: skip
    elif not rate_plant:
        keep("propulsion.motor_time_constant_s", UNCONFIRMED)
    fitted = result.battery
    for key in BATTERY_KEYS:
        name = key.split(".")[1]
        estimate = None if fitted is None else getattr(fitted, name)
        if estimate is not None and not estimate.refused:
            battery = replace(battery, **{name: estimate.value})
            sources[key] = ("identified", f"{source}: {format_estimate(estimate)} "
                            f"({_window(estimate)}); {estimate.method}")  # fmt: skip
        elif estimate is not None:
            keep(key, f"refused: {estimate.refused}")
        elif fitted is None:
            keep(key, f"not identified: {result.battery_reason}")
        else:
            why = fitted.efficiency_reason if "efficiency" in key else "no current after the disarm"
            keep(key, f"not identified: {why}")
    return replace(prior, body=body, propulsion=prop, battery=battery), sources


def _vibration(
    log: FlightLog,
    vehicle: Vehicle,
    hover_speed_radps: float,
    imu_rate_hz: float,
    defaults: Mapping[str, str],
    motors: str,
) -> tuple[Vehicle, dict[str, Source]]:
    """The ESCs' start, the IMU's white noise at rest and the vibration levels per operating
    point (:mod:`rig.identify.vibration`); a log without them keeps the generic ones and says
    why."""
    vehicle = replace(
        vehicle, vibration=replace(vehicle.vibration, reference_rotor_speed_radps=hover_speed_radps)
    )
    sources: dict[str, Source] = {
        "vibration.reference_rotor_speed_radps": ("identified", "the hover rotor speed above")
    }
    start = "propulsion.min_throttle"
    sources[start] = ("default", f"{defaults[start]}; the log's {motors}")
    try:
        measured = read_log_vibration(log)
        names = {point.name for point in measured.points}
        if {"idle", "stopped"} <= names:
            idle, stopped = measured.point("idle"), measured.point("stopped")
            # the accelerometer at the armed idle no louder than with the rotors stopped
            if np.sqrt(np.mean(idle.spectrum.sigma[0] ** 2)) <= np.sqrt(
                np.mean(stopped.spectrum.sigma[0] ** 2)
            ):
                throttle = max(idle.throttle) + ESC_START_MARGIN
                prop = replace(vehicle.propulsion, min_throttle=throttle)
                vehicle = replace(vehicle, propulsion=prop)
                sources[start] = (
                    "log",
                    f"the armed idle ({_spans(idle.windows_s)}, throttle "
                    f"{max(idle.throttle):.3f}, the log's {motors}) is no louder on the "
                    f"accelerometer than the rotors stopped: the ESCs start above it, "
                    f"+ {ESC_START_MARGIN}",
                )
        fitted, _ = fit_vibration(
            vehicle, measured, imu_rate_hz, tuple(n for n in FITTED_POINTS if n in names)
        )
    except (IdentificationError, LogError) as error:  # the rest of the file needs none of it
        for key in VIBRATION_KEYS + NOISE_KEYS:
            sources[key] = ("default", f"{defaults[key]}; not identified: {error}")
        return vehicle, sources
    source = f"rig identify {log.path.name} --vibration"
    rest = rest_point(vehicle, measured)
    if rest is None:
        for key in NOISE_KEYS:
            sources[key] = ("default", f"{defaults[key]}; no rest with the rotors stopped")
    else:
        span = _spans(rest.windows_s)
        sigma = _sigma_error(rest.windows_s, measured.stream_rate_hz)
        for key in NOISE_KEYS:
            sources[key] = ("identified", f"{source}: σ at rest ({span}) ± {sigma:.0%}")
    points = [p for p in measured.points if p.name in FITTED_POINTS and p is not rest]
    windows = "; ".join(f"{p.name} {_spans(p.windows_s)} ± "
                        f"{_sigma_error(p.windows_s, measured.stream_rate_hz):.0%}"
                        for p in points)  # fmt: skip
    for key in VIBRATION_KEYS:
        sources[key] = ("identified", f"{source}: band powers per point ({windows})")
    return fitted, sources


#: The values of the vibration fit (its levels per operating point) and of the white noise.
VIBRATION_KEYS = tuple(f"vibration.{key}" for key in ("level_rotor_speed_radps",
                       "accel_tone_level", "accel_broadband_level", "gyro_tone_level",
                       "gyro_broadband_level"))  # fmt: skip
NOISE_KEYS = tuple(f"imu.{key}" for key in ("gyro_noise_density_radps_per_sqrthz",
                   "accel_noise_density_mps2_per_sqrthz", "gyro_noise_axis_gain",
                   "accel_noise_axis_gain"))  # fmt: skip


def _logged(vehicle: Vehicle, params: Mapping[str, float]) -> tuple[Vehicle, dict[str, Source]]:
    """The pack's capacity from the log's parameters, where set."""
    capacity_mah = float(params.get("BAT1_CAPACITY", params.get("BAT_CAPACITY", -1.0)))
    if capacity_mah <= 0:
        return vehicle, {}
    vehicle = replace(vehicle, battery=replace(vehicle.battery, capacity_ah=capacity_mah / 1e3))
    return vehicle, {"battery.capacity_ah": ("log", f"BAT1_CAPACITY = {capacity_mah:g} mAh")}


def _motor_outputs(log: FlightLog) -> str:
    """The motors' output range as the file names it (PWM, DShot or CAN)."""
    outputs = motor_outputs(log)
    low, high = outputs.output_range
    return f"motor outputs {outputs.protocol} {low:g}-{high:g} {outputs.unit}"


def _sigma_error(windows: tuple[tuple[float, float], ...], rate_hz: float) -> float:
    """The relative standard error of a σ from the windows' samples: 1/√(2(N−1))."""
    samples = sum(end - start for start, end in windows) * rate_hz
    return 1.0 / math.sqrt(2.0 * max(samples - 1.0, 1.0))


def _spans(windows: tuple[tuple[float, float], ...]) -> str:
    return ", ".join(f"{a:.1f}-{b:.1f}" for a, b in windows) + " s"


def _window(estimate: Estimate) -> str:
    return f"{estimate.window_s[0]:.1f}-{estimate.window_s[1]:.1f} s"


def _rows(values: np.ndarray) -> tuple:
    """A matrix as the vehicle's nested tuples."""
    return tuple(tuple(float(v) for v in row) for row in values)


def _tables(vehicle: Vehicle) -> list[str]:
    """The vehicle's tables in file order (an absent optional one left out)."""
    return [f.name for f in fields(vehicle) if f.name != "name" and getattr(vehicle, f.name)]


def _document(vehicle: Vehicle) -> dict:
    """The vehicle as a parsed TOML document would hold it (an absent optional table left out)."""
    return {key: value for key, value in asdict(vehicle).items() if value is not None}


def _toml_value(value: str | float | tuple | list) -> str:
    """One TOML value: a string, a whole number, a float that reads back as one, an array."""
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, bool | int):
        return str(int(value))
    text = f"{value:.6g}"
    return text if any(c in text for c in ".en") else f"{text}.0"
