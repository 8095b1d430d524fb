"""Vehicle parameters: frozen dataclasses in SI units, loaded from TOML files.

A vehicle file has one table per dataclass below (``[body]``, ``[propulsion]``, ...); every
key is required, unknown keys are refused, and each value's provenance is a comment in the
file. Rotors are listed in PX4's order (quad X: 0 front-right CCW, 1 rear-left CCW,
2 front-left CW, 3 rear-right CW; other frames as PX4's ``CA_ROTORn`` of their airframe).
"""

import itertools
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field

from hil_config import (
    FieldError,
    NonNegative,
    Number,
    Positive,
    PositiveInteger,
    Text,
    UnitInterval,
    Vector3,
    load,
    parse,
    table,
)
from quad_model.frames import STANDARD_GRAVITY_MPS2

#: Where the bundled vehicle files live (``load_vehicle("f450_high_precision")``).
VEHICLES_DIR = Path(__file__).parent / "vehicles"
#: The rotor counts the model flies: quads, hexas and octos (flat or coaxial: Y6, X8), each
#: a compile-time case of the kernel (:mod:`quad_model.dynamics`).
ROTOR_COUNTS = (4, 6, 8)
MIN_ROTORS, MAX_ROTORS = min(ROTOR_COUNTS), max(ROTOR_COUNTS)
#: Two rotors whose hubs lie closer than this in the body x-y plane are a coaxial pair.
COAXIAL_HUB_TOLERANCE_M = 0.02
#: The bundled vehicle of each PX4 airframe (``SYS_AUTOSTART``; PX4's ROMFS init.d airframes).
AIRFRAMES = {4019: "x500_v2", 12001: "auriol_x8"}

#: Magnitudes (noise levels, coefficients, drag areas) are >= 0 per axis.
NonNegative3 = tuple[NonNegative, NonNegative, NonNegative]
#: One entry per rotor, MIN_ROTORS to MAX_ROTORS of them.
RotorPositions = Annotated[tuple[Vector3, ...], Field(min_length=MIN_ROTORS, max_length=MAX_ROTORS)]
RotorSpins = Annotated[tuple[Number, ...], Field(min_length=MIN_ROTORS, max_length=MAX_ROTORS)]
#: The vibration's per-operating-point level tables, in the IMU kernel's order
#: (triad accel then gyro; tones then broadband).
LEVEL_TABLES = (
    "accel_tone_level",
    "accel_broadband_level",
    "gyro_tone_level",
    "gyro_broadband_level",
)


class VehicleFileError(ValueError):
    """A vehicle file is missing, unreadable, or has a bad key; the message names it."""


def vehicle_for_airframe(parameters: Mapping[str, float], source: object) -> str:
    """The bundled vehicle of a PX4 log's airframe (its ``SYS_AUTOSTART`` in
    ``parameters``); a log without one, or of an airframe with no bundled vehicle, is one
    line naming ``source`` and the way round it."""
    autostart = parameters.get("SYS_AUTOSTART")
    if autostart is None:
        raise VehicleFileError(
            f"{source}: parameter SYS_AUTOSTART is not in the log; give --vehicle NAME|PATH"
        )
    if int(autostart) not in AIRFRAMES:
        known = ", ".join(f"{k} {v}" for k, v in AIRFRAMES.items())
        raise VehicleFileError(
            f"{source}: parameter SYS_AUTOSTART = {int(autostart)} is an airframe without a "
            f"bundled vehicle (known: {known}); --vehicle NAME|PATH overrides it"
        )
    return AIRFRAMES[int(autostart)]


@table
class BodyParams:
    """Rigid airframe: mass properties and aerodynamic drag of the body."""

    mass_kg: Positive
    #: Inertia tensor about the centre of mass, body FRD axes.
    inertia_kgm2: tuple[Vector3, Vector3, Vector3]
    #: Drag coefficient × reference area per body axis: F = -½ρ·CdA·|v|·v.
    drag_area_m2: NonNegative3
    #: Aerodynamic rotational damping per body axis: M = -c·|ω|·ω.
    angular_drag_nms2: NonNegative3

    def __post_init__(self) -> None:
        inertia = np.array(self.inertia_kgm2)
        if not np.allclose(inertia, inertia.T) or np.any(np.linalg.eigvalsh(inertia) <= 0):
            raise FieldError(
                "inertia_kgm2", self.inertia_kgm2, "must be symmetric positive definite"
            )


@table
class PropulsionParams:
    """ESC → motor → propeller, identical units; thrust and torque scale with air density."""

    #: Rotor hub positions relative to the centre of mass, FRD, PX4 motor order: one per
    #: rotor (4, 6 or 8; two hubs at the same x, y are a coaxial pair).
    position_frd_m: RotorPositions
    #: +1 for a rotor spinning counter-clockwise seen from above, -1 clockwise.
    spin_direction: RotorSpins
    thrust_coefficient_n_per_radps2: Positive
    torque_coefficient_nm_per_radps2: Positive
    #: Air density at which the two coefficients were measured.
    reference_air_density_kgpm3: Positive
    #: Motor rotor + propeller inertia about the spin axis.
    rotor_inertia_kgm2: Positive
    motor_time_constant_s: Positive
    #: Steady speed ω = slope·throttle + offset at the curve voltage (RflySim's C_R, ω_b).
    speed_slope_radps: Positive
    speed_offset_radps: Number
    #: Below this throttle the ESC does not spin the motor (start-up dead zone).
    min_throttle: UnitInterval
    #: Battery voltage at which the speed curve was measured; speed scales with voltage.
    speed_curve_voltage_v: Positive
    #: Induced (rotor) drag: F = -k·ω·v_perp per rotor, v_perp ⟂ to the rotor axis.
    rotor_drag_coefficient_ns_per_m_rad: NonNegative
    blade_count: PositiveInteger
    #: Axial inflow (RotorPy's k_z): F = -k·ω·v_axial per rotor along its axis, v_axial the
    #: air-relative velocity along it. A climbing rotor loses thrust and a descending one
    #: gains it at the same speed (blade element and momentum theory: dT/dV = -k·ω); 0: not
    #: modelled.
    axial_inflow_coefficient_ns_per_m_rad: NonNegative = 0.0
    #: The lower rotor of a coaxial pair works in the upper one's slipstream: at the same
    #: speed it gives this fraction of an isolated rotor's thrust and takes this fraction
    #: of its drag torque (1: not modelled). The upper rotor is unaffected.
    coaxial_thrust_factor: Annotated[Number, Field(gt=0, le=1)] = 1.0
    coaxial_torque_factor: Annotated[Number, Field(gt=0, le=1)] = 1.0

    def __post_init__(self) -> None:
        if any(s not in (-1.0, 1.0) for s in self.spin_direction):
            raise FieldError(
                "spin_direction", list(self.spin_direction), "must hold +1 (CCW) or -1 (CW)"
            )
        if len(self.position_frd_m) not in ROTOR_COUNTS:
            counts = ", ".join(map(str, ROTOR_COUNTS))
            reason = f"has {len(self.position_frd_m)} rotors; the model flies {counts}"
            raise FieldError("position_frd_m", list(self.position_frd_m), reason)
        if len(self.spin_direction) != len(self.position_frd_m):
            reason = f"needs one entry per rotor of position_frd_m ({len(self.position_frd_m)})"
            raise FieldError("spin_direction", list(self.spin_direction), reason)

    @property
    def rotor_count(self) -> int:
        return len(self.position_frd_m)

    @property
    def coaxial_lower(self) -> tuple[bool, ...]:
        """Per rotor: whether it is the lower one of a coaxial pair (its hub within
        COAXIAL_HUB_TOLERANCE_M of another's in x, y and below it, FRD z larger)."""
        hubs = np.array(self.position_frd_m)
        lower = []
        for x, y, z in hubs:
            near = np.hypot(hubs[:, 0] - x, hubs[:, 1] - y) < COAXIAL_HUB_TOLERANCE_M
            lower.append(bool(np.any(near & (hubs[:, 2] < z))))
        return tuple(lower)

    @property
    def thrust_factors(self) -> tuple[float, ...]:
        """Each rotor's thrust relative to an isolated rotor at the same speed."""
        return tuple(self.coaxial_thrust_factor if low else 1.0 for low in self.coaxial_lower)

    @property
    def torque_factors(self) -> tuple[float, ...]:
        """Each rotor's drag torque relative to an isolated rotor at the same speed."""
        return tuple(self.coaxial_torque_factor if low else 1.0 for low in self.coaxial_lower)


@table
class BatteryParams:
    """LiPo pack: open-circuit voltage linear in charge (PX4's estimator model) behind R."""

    cell_count: PositiveInteger
    capacity_ah: Positive
    cell_full_v: Positive
    cell_empty_v: Positive
    internal_resistance_ohm: NonNegative
    #: Shaft power / electrical power of motor + ESC.
    propulsion_efficiency: Annotated[Number, Field(gt=0, le=1)]
    avionics_power_w: NonNegative

    def __post_init__(self) -> None:
        if self.cell_empty_v >= self.cell_full_v:
            raise FieldError(
                "cell_empty_v", self.cell_empty_v, f"must be below cell_full_v ({self.cell_full_v})"
            )


@table
class ImuParams:
    """Accelerometer and gyroscope errors (discrete noise σ = density·√rate)."""

    gyro_noise_density_radps_per_sqrthz: NonNegative
    accel_noise_density_mps2_per_sqrthz: NonNegative
    gyro_bias_random_walk_radps2_per_sqrthz: NonNegative
    accel_bias_random_walk_mps3_per_sqrthz: NonNegative
    #: Standard deviation of the turn-on bias drawn once per run.
    gyro_turn_on_bias_std_radps: NonNegative
    accel_turn_on_bias_std_mps2: NonNegative
    #: Standard deviation of each axis's scale-factor error (fraction).
    gyro_scale_error_std: NonNegative
    accel_scale_error_std: NonNegative
    #: Standard deviation of the small axis misalignment angles (cross-axis sensitivity).
    misalignment_std_rad: NonNegative
    gyro_bias_tempco_radps_per_k: Number
    accel_bias_tempco_mps2_per_k: Number
    #: Die temperature above the outside air (board self-heating).
    self_heating_k: NonNegative
    #: Temperature at which the turn-on bias holds (factory calibration).
    reference_temperature_degc: Number
    #: White noise of each sensor axis (x, y, z) relative to the density: a board's axes
    #: need not be alike (the X500's accelerometer z is half as noisy at rest as x and y).
    gyro_noise_axis_gain: NonNegative3 = (1.0, 1.0, 1.0)
    accel_noise_axis_gain: NonNegative3 = (1.0, 1.0, 1.0)


@table
class VibrationParams:
    """IMU vibration from the rotors, given at a reference rotor speed; scales with ω², or
    with the levels measured at operating points.

    Each rotor adds tones at multiples of its shaft frequency (imbalance at 1×, blade
    passing at ``blade_count``×, ...) plus broadband frame noise.

    Operating points (``level_rotor_speed_radps``, ascending; empty: the ω² law): a real
    frame's vibration does not follow ω² (the X500's hover/idle σ ratio is 7, ω² gives 2.4),
    so each point gives, per triad and body axis, the level of the tones and of the
    broadband noise relative to the reference amplitudes × axis gains. A rotor between two
    points gets the linear interpolation, below the first point a level falling linearly to
    0 at rest, above the last the last level × (ω/ω_last)².
    """

    reference_rotor_speed_radps: Positive
    #: Per-rotor tone amplitude for shaft harmonics 1×, 2×, 3×, ...
    accel_harmonic_amplitude_mps2: tuple[NonNegative, ...]
    gyro_harmonic_amplitude_radps: tuple[NonNegative, ...]
    accel_broadband_std_mps2: NonNegative
    gyro_broadband_std_radps: NonNegative
    #: Relative vibration level of the body x, y, z axes.
    accel_axis_gain: NonNegative3
    gyro_axis_gain: NonNegative3
    level_rotor_speed_radps: tuple[Positive, ...] = ()
    accel_tone_level: tuple[NonNegative3, ...] = ()
    accel_broadband_level: tuple[NonNegative3, ...] = ()
    gyro_tone_level: tuple[NonNegative3, ...] = ()
    gyro_broadband_level: tuple[NonNegative3, ...] = ()

    def __post_init__(self) -> None:
        speeds = self.level_rotor_speed_radps
        if any(b <= a for a, b in itertools.pairwise(speeds)):
            raise FieldError("level_rotor_speed_radps", speeds, "must be strictly ascending")
        for name in LEVEL_TABLES:
            if len(getattr(self, name)) != len(speeds):
                reason = f"needs one [x, y, z] per rotor speed ({len(speeds)})"
                raise FieldError(name, getattr(self, name), reason)


@table
class BaroParams:
    """Barometer: white noise, a drifting offset, die temperature."""

    noise_std_pa: NonNegative
    drift_random_walk_pa_per_sqrts: NonNegative
    self_heating_k: NonNegative


@table
class MagParams:
    """Magnetometer: white noise and the vehicle's hard-iron offset (body FRD)."""

    noise_std_gauss: NonNegative
    hard_iron_frd_gauss: Vector3


@table
class GpsParams:
    """GNSS receiver: correlated position error, velocity noise, latency, fix rate."""

    horizontal_error_std_m: NonNegative
    vertical_error_std_m: NonNegative
    #: Correlation time of the first-order Gauss-Markov position error.
    error_correlation_time_s: Positive
    velocity_noise_std_mps: NonNegative
    latency_s: NonNegative
    #: The receiver's maximum navigation rate; the rate it reports at is the one the
    #: autopilot configures (CFG-RATE), at most this (``quad_model.sensors.GpsModel``).
    fix_rate_hz: Positive
    satellites_visible: PositiveInteger


@table
class RangefinderParams:
    """A rangefinder on the airframe: where it sits, where it looks, what it can range.

    The range is measured along ``axis_frd`` from ``position_frd_m`` (both body FRD, from
    the model's reference point, which touches the ground when landed) to the flat ground.
    Beyond ``max_range_m``, or tilted more than ``max_tilt_deg`` from straight down, the
    beam gets no return.
    """

    position_frd_m: Vector3
    #: Beam direction (normalised on load); straight down is (0, 0, 1).
    axis_frd: Vector3
    #: Farthest return (the nearest is 0: closer readings go to the autopilot, which
    #: judges them, as PX4 does with its own minimum).
    max_range_m: Positive
    #: One-sigma white noise on each measurement.
    noise_std_m: NonNegative
    max_tilt_deg: Annotated[Number, Field(gt=0, lt=90)]

    def __post_init__(self) -> None:
        norm = math.sqrt(sum(c * c for c in self.axis_frd))
        if norm < 1e-6:
            raise FieldError("axis_frd", self.axis_frd, "must be a direction (not zero)")
        object.__setattr__(self, "axis_frd", tuple(c / norm for c in self.axis_frd))


@table
class OpticalFlowParams:
    """A downward optical-flow camera (a PixArt PMW3901 class chip): its optics and the
    image quality it gets from the ground.

    It looks straight down the body z axis from ``position_frd_m``. Each camera frame
    measures how far the ground's image moved (an angle about body x and y); beyond
    ``max_rate_radps`` it loses the ground and reports no quality, closer than
    ``min_range_m`` the image is out of focus. The quality (SQUAL, 0..255 features) is
    ``squal_max`` on an ideal surface in good light, and falls with the surface's texture,
    with light below ``full_exposure_lux`` (the shutter is already at its longest) and with
    motion blur over the exposure.
    """

    position_frd_m: Vector3
    field_of_view_deg: Annotated[Number, Field(gt=0, lt=180)]
    #: Pixels across the field of view (square array): an image pixel's angle sets the blur.
    pixels: PositiveInteger
    frame_rate_hz: Positive
    max_rate_radps: Positive
    min_range_m: Positive
    #: Ground features counted on an ideal surface (texture 1) in good light.
    squal_max: Annotated[Number, Field(gt=0, le=255)]
    #: Below this illuminance the exposure is at its longest (one frame) and quality falls.
    full_exposure_lux: Positive
    #: One-sigma error of one frame's measured image motion, on a fully textured surface.
    noise_std_rad: NonNegative
    #: Tilted more than this from straight down, the camera no longer sees the ground.
    max_tilt_deg: Annotated[Number, Field(gt=0, lt=90)]

    @property
    def pixel_rad(self) -> float:
        """The angle one pixel spans."""
        return math.radians(self.field_of_view_deg) / self.pixels


@table
class Vehicle:
    """Everything the model needs to know about one vehicle."""

    name: Text
    body: BodyParams
    propulsion: PropulsionParams
    battery: BatteryParams
    imu: ImuParams
    vibration: VibrationParams
    baro: BaroParams
    mag: MagParams
    gps: GpsParams
    #: None: the vehicle carries no rangefinder.
    rangefinder: RangefinderParams | None = None
    #: None: the vehicle carries no optical-flow camera.
    optical_flow: OpticalFlowParams | None = None

    @property
    def hover_rotor_speed_radps(self) -> float:
        """Rotor speed at which all rotors, turning alike, carry the weight in the
        reference air."""
        p = self.propulsion
        weight_n = self.body.mass_kg * STANDARD_GRAVITY_MPS2
        return math.sqrt(weight_n / (sum(p.thrust_factors) * p.thrust_coefficient_n_per_radps2))


def load_vehicle(name_or_path: str | Path) -> Vehicle:
    """Load a vehicle file: a bundled name (``"x500_v2"``) or a path to a TOML file."""
    return load(Vehicle, name_or_path, VEHICLES_DIR, kind="vehicle", error=VehicleFileError)


def vehicle_from_dict(document: dict, source: str = "<dict>") -> Vehicle:
    """Build a :class:`Vehicle` from a parsed TOML document, checking every key."""
    return parse(Vehicle, document, source, VehicleFileError)
