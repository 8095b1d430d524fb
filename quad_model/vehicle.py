"""Vehicle parameters: frozen dataclasses in SI units, loaded from TOML files.

A vehicle file has one table per dataclass below (``[body]``, ``[propulsion]``, ...); every
key is required, unknown keys are refused, and each value's provenance is a comment in the
file. Rotors are listed in PX4's order (quad X: 0 front-right CCW, 1 rear-left CCW,
2 front-left CW, 3 rear-right CW).
"""

import math
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, get_origin

import numpy as np

from quad_model.frames import STANDARD_GRAVITY_MPS2
from quad_model.toml_file import read_toml_file

#: Where the bundled vehicle files live (``load_vehicle("f450_high_precision")``).
VEHICLES_DIR = Path(__file__).parent / "vehicles"
ROTOR_COUNT = 4


class VehicleFileError(ValueError):
    """A vehicle file is missing, unreadable, or has a bad key; the message names it."""


#: Allowed ranges of a scalar: name -> (test, how the error message states it).
_BOUNDS = {
    "non_negative": (lambda v: v >= 0, "must be >= 0"),
    "positive": (lambda v: v > 0, "must be > 0"),
    "signed": (lambda v: True, ""),
    "unit_interval": (lambda v: 0 <= v <= 1, "must be within 0..1"),
    "fraction": (lambda v: 0 < v <= 1, "must be within (0, 1]"),
}


def _spec(shape: tuple[int, ...] = (), bound: str = "non_negative") -> Any:
    """Field metadata: the array shape a TOML value must have (-1: any length) and, for a
    scalar, its allowed range. Magnitudes (noise levels, coefficients) default to >= 0."""
    return field(metadata={"shape": shape, "bound": bound})


@dataclass(frozen=True)
class BodyParams:
    """Rigid airframe: mass properties and aerodynamic drag of the body."""

    mass_kg: float = _spec(bound="positive")
    #: Inertia tensor about the centre of mass, body FRD axes.
    inertia_kgm2: tuple[tuple[float, ...], ...] = _spec(shape=(3, 3))
    #: Drag coefficient × reference area per body axis: F = -½ρ·CdA·|v|·v.
    drag_area_m2: tuple[float, ...] = _spec(shape=(3,))
    #: Aerodynamic rotational damping per body axis: M = -c·|ω|·ω.
    angular_drag_nms2: tuple[float, ...] = _spec(shape=(3,))


@dataclass(frozen=True)
class PropulsionParams:
    """ESC → motor → propeller, identical units; thrust and torque scale with air density."""

    #: Rotor hub positions relative to the centre of mass, FRD, PX4 motor order.
    position_frd_m: tuple[tuple[float, ...], ...] = _spec(shape=(ROTOR_COUNT, 3))
    #: +1 for a rotor spinning counter-clockwise seen from above, -1 clockwise.
    spin_direction: tuple[float, ...] = _spec(shape=(ROTOR_COUNT,))
    thrust_coefficient_n_per_radps2: float = _spec(bound="positive")
    torque_coefficient_nm_per_radps2: float = _spec(bound="positive")
    #: Air density at which the two coefficients were measured.
    reference_air_density_kgpm3: float = _spec(bound="positive")
    #: Motor rotor + propeller inertia about the spin axis.
    rotor_inertia_kgm2: float = _spec(bound="positive")
    motor_time_constant_s: float = _spec(bound="positive")
    #: Steady speed ω = slope·throttle + offset at the curve voltage (RflySim's C_R, ω_b).
    speed_slope_radps: float = _spec(bound="positive")
    speed_offset_radps: float = _spec(bound="signed")
    #: Below this throttle the ESC does not spin the motor (start-up dead zone).
    min_throttle: float = _spec(bound="unit_interval")
    #: Battery voltage at which the speed curve was measured; speed scales with voltage.
    speed_curve_voltage_v: float = _spec(bound="positive")
    #: Induced (rotor) drag: F = -k·ω·v_perp per rotor, v_perp ⟂ to the rotor axis.
    rotor_drag_coefficient_ns_per_m_rad: float = _spec()
    blade_count: int = _spec(bound="positive")


@dataclass(frozen=True)
class BatteryParams:
    """LiPo pack: open-circuit voltage linear in charge (PX4's estimator model) behind R."""

    cell_count: int = _spec(bound="positive")
    capacity_ah: float = _spec(bound="positive")
    cell_full_v: float = _spec(bound="positive")
    cell_empty_v: float = _spec(bound="positive")
    internal_resistance_ohm: float = _spec()
    #: Shaft power / electrical power of motor + ESC.
    propulsion_efficiency: float = _spec(bound="fraction")
    avionics_power_w: float = _spec()


@dataclass(frozen=True)
class ImuParams:
    """Accelerometer and gyroscope errors (discrete noise σ = density·√rate)."""

    gyro_noise_density_radps_per_sqrthz: float = _spec()
    accel_noise_density_mps2_per_sqrthz: float = _spec()
    gyro_bias_random_walk_radps2_per_sqrthz: float = _spec()
    accel_bias_random_walk_mps3_per_sqrthz: float = _spec()
    #: Standard deviation of the turn-on bias drawn once per run.
    gyro_turn_on_bias_std_radps: float = _spec()
    accel_turn_on_bias_std_mps2: float = _spec()
    #: Standard deviation of each axis's scale-factor error (fraction).
    gyro_scale_error_std: float = _spec()
    accel_scale_error_std: float = _spec()
    #: Standard deviation of the small axis misalignment angles (cross-axis sensitivity).
    misalignment_std_rad: float = _spec()
    gyro_bias_tempco_radps_per_k: float = _spec(bound="signed")
    accel_bias_tempco_mps2_per_k: float = _spec(bound="signed")
    #: Die temperature above the outside air (board self-heating).
    self_heating_k: float = _spec()
    #: Temperature at which the turn-on bias holds (factory calibration).
    reference_temperature_degc: float = _spec(bound="signed")


@dataclass(frozen=True)
class VibrationParams:
    """IMU vibration from the rotors, given at a reference rotor speed; scales with ω².

    Each rotor adds tones at multiples of its shaft frequency (imbalance at 1×, blade
    passing at ``blade_count``×, ...) plus broadband frame noise.
    """

    reference_rotor_speed_radps: float = _spec(bound="positive")
    #: Per-rotor tone amplitude for shaft harmonics 1×, 2×, 3×, ...
    accel_harmonic_amplitude_mps2: tuple[float, ...] = _spec(shape=(-1,))
    gyro_harmonic_amplitude_radps: tuple[float, ...] = _spec(shape=(-1,))
    accel_broadband_std_mps2: float = _spec()
    gyro_broadband_std_radps: float = _spec()
    #: Relative vibration level of the body x, y, z axes.
    accel_axis_gain: tuple[float, ...] = _spec(shape=(3,))
    gyro_axis_gain: tuple[float, ...] = _spec(shape=(3,))


@dataclass(frozen=True)
class BaroParams:
    """Barometer: white noise, a drifting offset, die temperature."""

    noise_std_pa: float = _spec()
    drift_random_walk_pa_per_sqrts: float = _spec()
    self_heating_k: float = _spec()


@dataclass(frozen=True)
class MagParams:
    """Magnetometer: white noise and the vehicle's hard-iron offset (body FRD)."""

    noise_std_gauss: float = _spec()
    hard_iron_frd_gauss: tuple[float, ...] = _spec(shape=(3,))


@dataclass(frozen=True)
class GpsParams:
    """GNSS receiver: correlated position error, velocity noise, latency, fix rate."""

    horizontal_error_std_m: float = _spec()
    vertical_error_std_m: float = _spec()
    #: Correlation time of the first-order Gauss-Markov position error.
    error_correlation_time_s: float = _spec(bound="positive")
    velocity_noise_std_mps: float = _spec()
    latency_s: float = _spec()
    fix_rate_hz: float = _spec(bound="positive")
    satellites_visible: int = _spec(bound="positive")


@dataclass(frozen=True)
class Vehicle:
    """Everything the model needs to know about one vehicle."""

    name: str
    body: BodyParams
    propulsion: PropulsionParams
    battery: BatteryParams
    imu: ImuParams
    vibration: VibrationParams
    baro: BaroParams
    mag: MagParams
    gps: GpsParams

    @property
    def hover_rotor_speed_radps(self) -> float:
        """Rotor speed at which four rotors carry the weight in the reference air."""
        p = self.propulsion
        weight_n = self.body.mass_kg * STANDARD_GRAVITY_MPS2
        return math.sqrt(weight_n / (ROTOR_COUNT * p.thrust_coefficient_n_per_radps2))


_SECTIONS = {
    "body": BodyParams,
    "propulsion": PropulsionParams,
    "battery": BatteryParams,
    "imu": ImuParams,
    "vibration": VibrationParams,
    "baro": BaroParams,
    "mag": MagParams,
    "gps": GpsParams,
}


def load_vehicle(name_or_path: str | Path) -> Vehicle:
    """Load a vehicle file: a bundled name (``"x500_v2"``) or a path to a TOML file."""
    document, path = read_toml_file(
        name_or_path,
        VEHICLES_DIR,
        kind="vehicle",
        error=VehicleFileError,
        invalid_toml="not a readable TOML file",
    )
    return vehicle_from_dict(document, str(path))


def vehicle_from_dict(document: dict[str, Any], source: str = "<dict>") -> Vehicle:
    """Build a :class:`Vehicle` from a parsed TOML document, checking every key."""
    unknown = sorted(set(document) - set(_SECTIONS) - {"name"})
    if unknown:
        raise VehicleFileError(f"{source}: unknown key {unknown[0]!r}")
    if not isinstance(document.get("name"), str):
        raise VehicleFileError(f"{source}: key 'name' is missing or not a string")
    sections = {}
    for section, cls in _SECTIONS.items():
        table = document.get(section)
        if not isinstance(table, dict):
            raise VehicleFileError(f"{source}: table [{section}] is missing")
        sections[section] = _read_table(table, cls, f"{source}: [{section}]")
    vehicle = Vehicle(name=document["name"], **sections)
    _check_consistency(vehicle, source)
    return vehicle


def _read_table(table: dict[str, Any], cls: type, where: str) -> Any:
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(table) - set(names))
    if unknown:
        raise VehicleFileError(f"{where} unknown key {unknown[0]!r}")
    values = {}
    for f in fields(cls):
        if f.name not in table:
            raise VehicleFileError(f"{where} key {f.name!r} is missing")
        values[f.name] = _read_value(table[f.name], f, f"{where} {f.name}")
    return cls(**values)


def _read_value(raw: Any, f: Any, where: str) -> Any:
    shape = f.metadata["shape"]
    if shape:
        try:
            array = np.array(raw, dtype=float)
        except (TypeError, ValueError):
            raise VehicleFileError(f"{where} = {raw!r} is not a numeric array") from None
        if array.ndim != len(shape) or any(
            s not in (-1, n) for s, n in zip(shape, array.shape, strict=True)
        ):
            wanted = "×".join("N" if s == -1 else str(s) for s in shape)
            raise VehicleFileError(f"{where} = {raw!r} must be an array of shape {wanted}")
        if not np.all(np.isfinite(array)):
            raise VehicleFileError(f"{where} = {raw!r} has a non-finite value")
        return tuple(array.tolist()) if array.ndim == 1 else tuple(tuple(r) for r in array.tolist())
    integer = f.type is int or get_origin(f.type) is int
    if (
        isinstance(raw, bool)
        or not isinstance(raw, int | float)
        or (integer and not isinstance(raw, int))
    ):
        kind = "an integer" if integer else "a number"
        raise VehicleFileError(f"{where} = {raw!r} is not {kind}")
    if not math.isfinite(raw):
        raise VehicleFileError(f"{where} = {raw!r} is not finite")
    in_range, rule = _BOUNDS[f.metadata["bound"]]
    if not in_range(raw):
        raise VehicleFileError(f"{where} = {raw!r} {rule}")
    return int(raw) if integer else float(raw)


def _check_consistency(vehicle: Vehicle, source: str) -> None:
    inertia = np.array(vehicle.body.inertia_kgm2)
    if not np.allclose(inertia, inertia.T) or np.any(np.linalg.eigvalsh(inertia) <= 0):
        raise VehicleFileError(f"{source}: [body] inertia_kgm2 must be symmetric positive definite")
    spins = vehicle.propulsion.spin_direction
    if any(s not in (-1.0, 1.0) for s in spins):
        raise VehicleFileError(
            f"{source}: [propulsion] spin_direction = {list(spins)} must hold +1 (CCW) or -1 (CW)"
        )
    battery = vehicle.battery
    if battery.cell_empty_v >= battery.cell_full_v:
        raise VehicleFileError(
            f"{source}: [battery] cell_empty_v = {battery.cell_empty_v} must be below "
            f"cell_full_v = {battery.cell_full_v}"
        )
