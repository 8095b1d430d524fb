"""What an identification found: each estimate with its method, data window and uncertainty."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from rig.errors import RigError

#: Above this relative uncertainty of B an inertia is not called identified: the paper's
#: low-precision inertias differ from the measured ones by 40-50 % (f450_low_precision.toml),
#: so a looser estimate
#: could not tell a high-precision model from a low-precision one.
MAX_RELATIVE_UNCERTAINTY = 0.3


AXES = ("roll", "pitch", "yaw")


class IdentificationError(RigError):
    """The log cannot give an identification (missing topic, no hover, ...); one line."""


@dataclass(frozen=True)
class Estimate:
    """One identified number: value ± uncertainty (same unit), how, and from which data;
    ``refused`` says why it is not a result (:mod:`rig.identify.bounds`), "" when it is."""

    value: float
    uncertainty: float
    method: str
    window_s: tuple[float, float]
    refused: str = ""

    @property
    def relative_uncertainty(self) -> float:
        return abs(self.uncertainty / self.value) if self.value else math.inf


@dataclass(frozen=True)
class RotorLine:
    """The rotors' once-per-revolution line in the log's IMU stream, read in hover."""

    #: Where the line is (Hz); ± the spread of the four rotors' lines.
    frequency: Estimate
    #: Pearson r of the line's frequency with command × voltage across the flight.
    correlation: float
    #: k_T = mg/(4ω_h²) at the vehicle's reference air density.
    thrust_coefficient: Estimate


@dataclass(frozen=True)
class BatteryIdentification:
    """The pack and the power it delivers, from ``battery_status``."""

    internal_resistance_ohm: Estimate
    #: None when the log holds no current after the disarm.
    avionics_power_w: Estimate | None
    #: Shaft power over electrical power into the motors, in hover; None when implausible
    #: or not measured (``efficiency_reason`` says why).
    propulsion_efficiency: Estimate | None
    efficiency_reason: str = ""


@dataclass(frozen=True)
class HoverIdentification:
    """Hover throttle and the speed curve through it."""

    windows_s: tuple[tuple[float, float], ...]
    #: Mean ``actuator_motors`` per motor (PX4's normalized motor command, 0..1).
    motor_command: tuple[float, ...]
    #: ESC throttle (model convention, PWM 1000..2000 µs → 0..1), mean of the motors.
    throttle: Estimate
    thrust_setpoint: float
    #: PX4's own estimate (``hover_thrust_estimate``), None when the log has none.
    px4_hover_thrust: float | None
    battery_voltage_v: float
    air_density_kgpm3: float
    rotor_speed_radps: float
    speed_offset_radps: Estimate
    speed_slope_radps: float
    #: Where the thrust of the hover's mean motor commands balances (body x, y, m from the
    #: rotors' centre): a centre of mass off the middle makes the autopilot trim the motors
    #: apart, and the rotors then turn at different speeds (their IMU tones beat).
    centre_of_mass_frd_m: tuple[float, float] = (0.0, 0.0)
    #: The rotors' line in the IMU; None (``rotor_line_reason`` says why).
    rotor_line: RotorLine | None = None
    rotor_line_reason: str = ""
    #: ω_h the ESCs measured (``esc_status``), first choice for ω_h; None:
    #: ``measured_speed_reason`` says why.
    measured_rotor_speed: Estimate | None = None
    measured_speed_reason: str = ""
    #: k_T = mg/(Nω_h²) at the reference density from the measured ω_h (ESCs, else the
    #: rotor line); None when ω_h is the vehicle's own √(mg/4k_T).
    thrust_coefficient: Estimate | None = None


@dataclass(frozen=True)
class AxisIdentification:
    """Rate-loop plant of one body axis.

    ``identified`` False: no fit, the numbers are None. ``reliable`` False: fitted, but B (so
    I) is not confirmed within MAX_RELATIVE_UNCERTAINTY by the whole-flight window; ``reason``
    says why. τ_m counts only when ``motor_lag_identified``.
    """

    axis: str
    identified: bool
    reason: str
    reliable: bool = False
    band_hz: tuple[float, float] | None = None
    fit_points: int = 0
    control_effectiveness_radps2: Estimate | None = None
    motor_time_constant_s: Estimate | None = None
    motor_lag_identified: bool = False
    delay_s: Estimate | None = None
    torque_per_unit_nm: float | None = None
    inertia_kgm2: Estimate | None = None
    #: The same fit over the whole airborne span: an independent-window cross-check.
    cross_check_inertia_kgm2: float | None = None


@dataclass(frozen=True)
class Identification:
    """What one log says about one vehicle; ``notes`` are caveats to read with the numbers."""

    log: Path
    vehicle_name: str
    sample_rate_hz: float
    gyro_cutoff_hz: float
    pwm_range_us: tuple[float, float]
    hover: HoverIdentification
    axes: tuple[AxisIdentification, ...]
    notes: tuple[str, ...]
    #: None (``battery_reason`` says why) when the log cannot give it.
    battery: BatteryIdentification | None = None
    battery_reason: str = ""

    def axis(self, name: str) -> AxisIdentification:
        return self.axes[AXES.index(name)]
