"""Vehicle parameters identified from a flight log (``rig identify LOG``): hover throttle and
the speed curve, roll/pitch control effectiveness, motor lag and delay, and the inertia.

The paper's high-precision model has "all model parameters accurately measured or obtained
by system identification"; this module is the identification half, for any PX4-style ULog
(a real flight, PX4 SITL, or the rig's reference autopilot) at any logging rate.

Methods, each reported with its data window and an uncertainty:

- **Hover**: steady windows found automatically (airborne, small velocity and body rates).
  The ESC throttle there is ``actuator_motors`` mapped through the log's PWM range
  (``PWM_MAIN/AUX_MINn/MAXn`` of the motor outputs) onto the model's 1000-2000 µs throttle
  (:func:`quad_model.frames.pwm_to_throttle`). The hover rotor speed ω_h must sit at that
  throttle on the speed curve; the curve's full-throttle point is kept and its offset solved
  for. ω_h is measured where the log shows it, else ω_h = √(mg/4k_T) with the vehicle's k_T.
- **Rotor line**: the rotors' once-per-revolution line (prop and motor imbalance) is the
  strongest peak of the accelerometer's spectrum in hover. A logged stream folds lines above
  its Nyquist frequency, so the line must also *rise* with the motor command × voltage
  across the flight (a folded line falls; neither: not identified), and the rotors' shaft
  power at that speed must stay below the battery's power into the motors (a harmonic read
  as the 1× would not). Then ω_h = 2πf and k_T = mg/(4ω_h²), the thrust coefficient at the
  vehicle's reference air density.
- **Battery**: V = E₀ − s·Q − R·I over the armed flight (``battery_status``: voltage, current,
  charge drawn) by least squares gives the internal resistance R; the current after the
  disarm (rotors stopped) the avionics' power; the hover's electrical power against the
  rotors' shaft power 4·k_Q·ω_h³ (the vehicle's torque coefficient) the propulsion efficiency.
- **Rate-loop plant** per axis: the frequency response torque set-point → body rate, fitted
  to ``B·e^{−sd}/(s(τ_m s+1))`` times the log's gyro low-pass (``IMU_GYRO_CUTOFF``,
  PX4's 2nd-order Butterworth), so the filter's phase is not blamed on the motors. The data
  are closed-loop: where the loop's own noise dominates (above a few Hz in hover), the plain
  H1 estimate torque→rate tends to −1/C(s), the inverse of the rate controller, not the plant
  (on the X500 log: phase ≈ +170°, |H| flat from 3 to 20 Hz). So the response is the
  joint input-output estimate with the rate set-point as instrument,
  G = Ĥ(rate_sp→rate) / Ĥ(rate_sp→torque_sp) (Ljung, *System Identification*, §13.5), each
  leg from :func:`credibility.spectral.estimate_response` and both gated on coherence.
- **Inertia**: I = (body torque per unit normalized torque at hover) / B. The numerator is
  computed through the real parts: the reference autopilot's mixer
  (:class:`rig.autopilots.reference.control.ControlAllocator` with the log's ``CA_ROTOR*`` geometry)
  turns a torque set-point into motor commands, and the vehicle model on its thrust stand
  (:class:`quad_model.model.QuadModel`, ``Mount.THRUST_STAND``), fed from a bench supply at
  the log's hover voltage, turns them into a moment.
- **Yaw** is not identified: its reaction-torque path (rotor drag plus spin-up torque) is not
  the rate model above, and ordinary flying excites it little; the result says so.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from rich.table import Table
from scipy import optimize, signal
from scipy.ndimage import uniform_filter1d

from credibility.errors import CredibilityError
from credibility.indices import coherence_weight
from credibility.layouts import derive_missing, sources_of_missing
from credibility.logs import read_ulog
from credibility.spectral import default_windows, estimate_response, log_grid
from quad_model.frames import STANDARD_GRAVITY_MPS2, pwm_to_throttle
from quad_model.model import Mount, QuadModel
from quad_model.vehicle import ROTOR_COUNT, Vehicle
from rig.apps.replay import AIRFRAMES, motor_pwm_range
from rig.autopilots.reference.control import ControlAllocator
from rig.autopilots.reference.params import Parameters
from rig.errors import RigError

#: Hover: airborne, RMS over HOVER_SMOOTH_S of |v| and of each body rate below these, for at
#: least MIN_HOVER_S (a position-hold hover with a pilot's small corrections qualifies).
HOVER_SMOOTH_S = 1.0
HOVER_MAX_SPEED_MPS = 0.6
HOVER_MAX_RATE_RADPS = 0.25
MIN_HOVER_S = 3.0
#: … and the thrust set-point within this fraction of its airborne median.
HOVER_THRUST_BAND = 0.2
#: The rotor line: the strongest peak of the accelerometer PSD (three axes summed, 1 Hz
#: resolution) above ROTOR_LINE_MIN_HZ in the hover windows; it sits at the power-weighted
#: mean frequency within ± ROTOR_LINE_BAND of the peak (four rotors at slightly different
#: speeds), ± the power-weighted spread there.
ROTOR_LINE_MIN_HZ = 10.0
ROTOR_LINE_BAND = 0.1
#: Folding check: in FOLD_WINDOW_S windows over the airborne span, the line's frequency
#: (within ± FOLD_BAND of the hover line) against the mean motor command × voltage; it must
#: correlate with |Pearson r| ≥ FOLD_MIN_CORRELATION over at least FOLD_MIN_WINDOWS windows.
FOLD_WINDOW_S = 2.0
FOLD_BAND = 0.3
FOLD_MIN_CORRELATION = 0.5
FOLD_MIN_WINDOWS = 8
#: Battery: the after-disarm current is the avionics' once the rotors have coasted down.
DISARM_SETTLE_S = 0.5
#: Both legs of the joint input-output estimate must reach this coherence (γ²) at a
#: frequency for it to enter the fit: below ≈ 0.4 the random error of one leg exceeds
#: ≈ 30 % with the segment counts of a one-minute log (Bendat & Piersol ε_r).
COHERENCE_MIN = 0.4
#: At least this many gated grid points (of GRID_POINTS) per axis, or the axis is reported
#: as not identifiable: three parameters need a margin of degrees of freedom.
MIN_FIT_POINTS = 6
GRID_POINTS = 40
#: Upper end of the analysis band as a fraction of the log's sample rate (10 Hz at 50 Hz
#: logging): nearer the Nyquist frequency the folded torque noise turns the phase (-30° at
#: 15 Hz on a rig flight logged at 50 Hz).
BAND_TOP_FRACTION = 0.2
#: Below this log rate the rate loop's torque noise (D term) folds into the analysis band and
#: biases B low, by how much depends on that noise; ALIASING_BIAS bounds it (rig flights
#: resampled to 50 Hz read B 1-20 % low, tests/rig/test_identify.py) and enters B's uncertainty.
ALIASING_RATE_HZ = 100.0
ALIASING_BIAS = 0.25
#: Above this relative uncertainty of B an inertia is not called identified: the paper's
#: low-precision inertias differ from the measured ones by 40-50 % (f450_low_precision.toml),
#: so a looser estimate
#: could not tell a high-precision model from a low-precision one.
MAX_RELATIVE_UNCERTAINTY = 0.3
#: Fit bounds: τ_m and d between 1 ms and 0.2 s cover hobby to heavy-lift propulsion.
TAU_BOUNDS_S = (1e-3, 0.2)
DELAY_BOUNDS_S = (0.0, 0.2)
#: Torque set-point step for the numerical derivative through mixer and thrust stand
#: (small: no motor saturates around hover).
TORQUE_STEP = 0.05
#: Thrust-stand settling time in motor time constants (e^-20: settled to 2e-9).
SETTLE_TIME_CONSTANTS = 20.0
_GEOMETRY_PARAM = re.compile(rf"CA_ROTOR[0-{ROTOR_COUNT - 1}]_(PX|PY|KM)")
_AXES = ("roll", "pitch", "yaw")
_TOPICS = (
    "vehicle_torque_setpoint",
    "vehicle_angular_velocity",
    "vehicle_rates_setpoint",
    "actuator_motors",
    "vehicle_thrust_setpoint",
    "hover_thrust_estimate",
    "battery_status",
    "vehicle_local_position",
    "vehicle_land_detected",
    "vehicle_air_data",
    "sensor_combined",
    "actuator_armed",
)


class IdentificationError(RigError):
    """The log cannot give an identification (missing topic, no hover, ...); one line."""


@dataclass(frozen=True)
class Estimate:
    """One identified number: value ± uncertainty (same unit), how, and from which data."""

    value: float
    uncertainty: float
    method: str
    window_s: tuple[float, float]

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
    #: The measured hover rotor speed; None (``rotor_line_reason`` says why): ω_h from k_T.
    rotor_line: RotorLine | None = None
    rotor_line_reason: str = ""


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
        return self.axes[_AXES.index(name)]


# ------------------------------------------------------------------ reading the log
@dataclass(frozen=True)
class _Log:
    path: Path
    topics: Mapping[str, Mapping[str, NDArray[np.float64]]]
    params: Mapping[str, float]
    #: Topics of a newer PX4 derived from an older log's (:mod:`credibility.layouts`).
    derived: tuple[str, ...] = ()

    def topic(self, name: str, why: str) -> Mapping[str, NDArray[np.float64]]:
        data = self.topics.get(name)
        if data is None:
            raise IdentificationError(f"{self.path}: no topic {name!r} ({why})")
        return data

    def series(self, name: str, field: str, why: str) -> tuple[NDArray, NDArray]:
        """(time s, values) of one field, sorted, repeated stamps dropped."""
        data = self.topic(name, why)
        if field not in data:
            raise IdentificationError(f"{self.path}: topic {name!r} has no field {field!r}")
        time_s, values = data["t"], data[field].astype(float)
        keep = np.concatenate(([True], np.diff(time_s) > 0))
        return time_s[keep], values[keep]


def _read_log(path: Path) -> _Log:
    if not path.is_file():
        raise IdentificationError(f"{path}: log file not found")
    try:
        ulog, _ = read_ulog(path, _TOPICS)  # its warnings (a skipped damaged message) don't matter
        topics = {d.name: dict(d.data) for d in ulog.data_list if d.multi_id == 0}
        # An older PX4's log: read what the missing topics derive from (a second pass, so a
        # current log never holds sensor_combined in memory).
        sources = sources_of_missing(topics, _TOPICS)
        if sources:
            older, _ = read_ulog(path, sources)
            topics.update((d.name, dict(d.data)) for d in older.data_list if d.multi_id == 0)
    except CredibilityError as error:
        raise IdentificationError(str(error)) from None
    params = dict(ulog.initial_parameters)
    derived = derive_missing(topics, params, _TOPICS)
    for name, data in topics.items():
        # the rates at their measurement time, so the fitted delay is physical
        measured = name == "vehicle_angular_velocity" and "timestamp_sample" in data
        stamp = data["timestamp_sample" if measured else "timestamp"]
        order = np.argsort(stamp, kind="stable")
        topics[name] = {k: np.asarray(v)[order] for k, v in data.items()}
        topics[name]["t"] = stamp[order] * 1e-6
    return _Log(path, topics, params, derived)


# ------------------------------------------------------------------ public entry point
def identify_vehicle(
    log_path: str | Path,
    vehicle: Vehicle,
    excitation_window_s: tuple[float, float] | None = None,
) -> Identification:
    """Identify hover, roll/pitch plant and inertia of ``vehicle`` from one flight log.

    ``excitation_window_s`` is the span for the rate-loop fit (default: the whole airborne
    span); the whole airborne span is always fitted too, as a cross-check.
    """
    log = _read_log(Path(log_path))
    sample_rate_hz = _sample_rate_hz(log)
    gyro_cutoff_hz = float(log.params.get("IMU_GYRO_CUTOFF", 0.0))
    pwm_range = motor_pwm_range(log.params, log.path)
    airborne = _airborne_span(log)
    window = excitation_window_s or airborne
    if not (airborne[0] <= window[0] < window[1] <= airborne[1]):
        raise IdentificationError(
            f"{log.path}: excitation window {window[0]:g}-{window[1]:g} s is not inside the "
            f"airborne span {airborne[0]:.1f}-{airborne[1]:.1f} s"
        )
    hover = _identify_hover(log, vehicle, pwm_range)
    identified_vehicle = replace(
        vehicle,
        propulsion=replace(
            vehicle.propulsion,
            speed_offset_radps=hover.speed_offset_radps.value,
            speed_slope_radps=hover.speed_slope_radps,
        ),
    )
    torque_per_unit = torque_per_unit_nm(
        identified_vehicle,
        log.params,
        float(np.mean(hover.motor_command)),
        pwm_range,
        hover.battery_voltage_v,
        hover.air_density_kgpm3,
    )
    axes = [
        _identify_axis(
            log, axis, window, airborne, sample_rate_hz, gyro_cutoff_hz, torque_per_unit[axis]
        )
        for axis in range(2)
    ]
    axes.append(
        AxisIdentification(
            "yaw",
            identified=False,
            reason="not identifiable: the yaw reaction torque (rotor drag + spin-up) is not "
            "the B/(s(τs+1)) plant and flight excites it little; I_zz kept from the vehicle",
        )
    )
    battery, battery_reason = _identify_battery(log, hover, vehicle)
    return Identification(
        log=log.path,
        vehicle_name=vehicle.name,
        sample_rate_hz=sample_rate_hz,
        gyro_cutoff_hz=gyro_cutoff_hz,
        pwm_range_us=pwm_range,
        hover=hover,
        axes=tuple(axes),
        notes=(*log.derived, *_notes(sample_rate_hz, log.params)),
        battery=battery,
        battery_reason=battery_reason,
    )


def _notes(sample_rate_hz: float, params: Mapping[str, float]) -> tuple[str, ...]:
    notes = []
    if sample_rate_hz < ALIASING_RATE_HZ:
        notes.append(
            f"log rate {sample_rate_hz:.0f} Hz: the torque set-point's noise above "
            f"{sample_rate_hz / 2:.0f} Hz (rate D-term) folds into the band, so B reads low and "
            f"I high (≤ {ALIASING_BIAS:.0%}, in the uncertainty); log the rate topics at "
            "≥ 200 Hz (SDLOG_PROFILE high rate) for a clean estimate"
        )
    if params.get("THR_MDL_FAC", 0.0) != 0.0:
        # the mixer here allocates with a thrust linear in the motor command, as PX4 with
        # THR_MDL_FAC = 0; a non-linear thrust model changes the torque per unit command
        notes.append(
            f"THR_MDL_FAC = {params['THR_MDL_FAC']:g}: the torque per unit assumes PX4's linear "
            "thrust model (THR_MDL_FAC = 0), so I carries that error too"
        )
    return tuple(notes)


def _sample_rate_hz(log: _Log) -> float:
    time_s, _ = log.series("vehicle_angular_velocity", "xyz[0]", "body rates for the rate fit")
    if time_s.size < 100:
        raise IdentificationError(
            f"{log.path}: vehicle_angular_velocity has only {time_s.size} samples"
        )
    return float((time_s.size - 1) / (time_s[-1] - time_s[0]))


def _airborne_span(log: _Log) -> tuple[float, float]:
    time_s, landed = log.series("vehicle_land_detected", "landed", "airborne span")
    flying = time_s[landed < 0.5]
    if flying.size == 0:
        raise IdentificationError(f"{log.path}: the vehicle never left the ground")
    return float(flying[0]), float(flying[-1])


# ------------------------------------------------------------------ hover
def hover_windows(log_path: str | Path) -> tuple[tuple[float, float], ...]:
    """Steady-hover spans of a log: airborne, RMS |v| ≤ HOVER_MAX_SPEED_MPS (vz alone where
    PX4 flags vx, vy invalid), RMS of every body rate ≤ HOVER_MAX_RATE_RADPS (over
    HOVER_SMOOTH_S) and the thrust within HOVER_THRUST_BAND of its airborne median, for at
    least MIN_HOVER_S."""
    return _hover_windows(_read_log(Path(log_path)))


def _hover_windows(log: _Log) -> tuple[tuple[float, float], ...]:
    why = "velocity for hover detection"
    time_s, vz = log.series("vehicle_local_position", "vz", why)
    horizontal_sq = sum(log.series("vehicle_local_position", f, why)[1] ** 2 for f in ("vx", "vy"))
    if "v_xy_valid" in log.topic("vehicle_local_position", why):
        # without a horizontal aid (no GNSS: the 8S quad's log) PX4 flags vx, vy invalid and
        # they drift to nonsense; the vertical speed (baro) and the rates still find a hover
        horizontal_sq *= log.series("vehicle_local_position", "v_xy_valid", why)[1]
    speed_sq = vz**2 + horizontal_sq
    t_landed, landed = log.series("vehicle_land_detected", "landed", "airborne span")
    landed_now = landed[np.clip(np.searchsorted(t_landed, time_s, "right") - 1, 0, None)]
    # averaged over HOVER_SMOOTH_S: a pilot's small corrections are hover, a manoeuvre not
    span = max(1, round(HOVER_SMOOTH_S / np.median(np.diff(time_s))))
    # a running mean of squares can dip below zero by rounding: clip before the root
    mean_speed_sq = np.maximum(uniform_filter1d(speed_sq, span), 0.0)
    steady = (landed_now < 0.5) & (np.sqrt(mean_speed_sq) <= HOVER_MAX_SPEED_MPS)
    # the collective thrust near its airborne median: the land detector calls a heavy
    # vehicle's slow spin-up airborne before it lifts (the 8S quad: 110-120 s at thrust
    # 0.2-0.55 against 0.65 in hover), and a climb without velocity (no GNSS) looks level
    if "vehicle_thrust_setpoint" in log.topics:  # else the hover's thrust names it missing
        t_thrust, thrust = log.series("vehicle_thrust_setpoint", "xyz[2]", "hover detection")
        thrust = np.interp(time_s, t_thrust, -thrust)
        median = float(np.median(thrust[landed_now < 0.5])) if np.any(landed_now < 0.5) else 0.0
        steady &= np.abs(thrust - median) <= HOVER_THRUST_BAND * median
    for axis in range(3):
        t_rate, rate = log.series("vehicle_angular_velocity", f"xyz[{axis}]", "hover detection")
        rate_sq = np.interp(
            time_s,
            t_rate,
            uniform_filter1d(rate**2, max(1, round(HOVER_SMOOTH_S / np.median(np.diff(t_rate))))),
        )
        steady &= np.sqrt(np.maximum(rate_sq, 0.0)) <= HOVER_MAX_RATE_RADPS
    windows = []
    start = None
    for t, ok in zip(time_s, np.append(steady[:-1], False), strict=True):
        if ok and start is None:
            start = t
        elif not ok and start is not None:
            if t - start >= MIN_HOVER_S:
                windows.append((float(start), float(t)))
            start = None
    return tuple(windows)


def _mean_in(time_s: NDArray, values: NDArray, windows) -> NDArray:
    mask = np.zeros(time_s.size, dtype=bool)
    for a, b in windows:
        mask |= (time_s >= a) & (time_s < b)
    return values[mask]


def _identify_hover(
    log: _Log, vehicle: Vehicle, pwm_range: tuple[float, float]
) -> HoverIdentification:
    windows = _hover_windows(log)
    if not windows:
        raise IdentificationError(
            f"{log.path}: no hover window found (airborne, RMS |v| ≤ {HOVER_MAX_SPEED_MPS} m/s "
            f"and |rates| ≤ {HOVER_MAX_RATE_RADPS} rad/s for ≥ {MIN_HOVER_S:g} s)"
        )
    span = (windows[0][0], windows[-1][1])
    commands = []
    for motor in range(ROTOR_COUNT):
        t, u = log.series("actuator_motors", f"control[{motor}]", "hover motor commands")
        commands.append(_mean_in(t, u, windows))
    commands = np.array(commands)  # motors × samples
    pwm = pwm_range[0] + (pwm_range[1] - pwm_range[0]) * commands
    throttle_samples = pwm_to_throttle(pwm).mean(axis=0)
    throttle = float(throttle_samples.mean())
    t, thrust_z = log.series("vehicle_thrust_setpoint", "xyz[2]", "hover thrust")
    thrust_sp = -float(_mean_in(t, thrust_z, windows).mean())
    px4_hover = None
    if "hover_thrust_estimate" in log.topics:
        t, h = log.series("hover_thrust_estimate", "hover_thrust", "")
        in_hover = _mean_in(t, h, windows)
        px4_hover = float(in_hover.mean()) if in_hover.size else None
    t, volts = log.series("battery_status", "voltage_v", "the speed curve needs the voltage")
    voltage = float(_mean_in(t, volts, windows).mean())
    prop = vehicle.propulsion
    if "vehicle_air_data" in log.topics:
        t, rho = log.series("vehicle_air_data", "rho", "")
        density = float(_mean_in(t, rho, windows).mean())
        density_source = "vehicle_air_data.rho"
    else:
        density = prop.reference_air_density_kgpm3
        density_source = "the vehicle's reference density (log has no vehicle_air_data)"
    line, line_reason = _identify_rotor_line(log, windows, vehicle, density)
    if line is None:
        k_t = prop.thrust_coefficient_n_per_radps2 * density / prop.reference_air_density_kgpm3
        speed = math.sqrt(vehicle.body.mass_kg * STANDARD_GRAVITY_MPS2 / (ROTOR_COUNT * k_t))
        speed_std = 0.0
        speed_source = f"ω_h = √(mg/4k_T) = {speed:.0f} rad/s (ρ from {density_source})"
    else:
        speed = 2.0 * math.pi * line.frequency.value
        speed_std = 2.0 * math.pi * line.frequency.uncertainty
        speed_source = f"ω_h = {speed:.0f} rad/s (the rotor line)"
    # quad_model.dynamics: ω = (slope·σ + offset)·V/V_curve. Keep ω(σ=1) = slope + offset
    # (the KV estimate at V_curve) and move the offset so that ω(σ_h) = ω_h at V_hover.
    full = prop.speed_slope_radps + prop.speed_offset_radps
    curve_speed = speed * prop.speed_curve_voltage_v / voltage
    slope = (full - curve_speed) / (1.0 - throttle)
    throttle_std = float(throttle_samples.std())
    # offset = full − (full − ω_c)/(1 − σ_h): the throttle's spread and ω_h's, in quadrature
    offset_std = math.hypot(
        (full - curve_speed) / (1.0 - throttle) ** 2 * throttle_std,
        speed_std * prop.speed_curve_voltage_v / voltage / (1.0 - throttle),
    )
    window = (span[0], span[1])
    method_hover = f"{len(windows)} hover window(s), {throttle_samples.size} samples"
    return HoverIdentification(
        windows_s=windows,
        motor_command=tuple(float(c.mean()) for c in commands),
        throttle=Estimate(
            throttle,
            throttle_std,
            f"actuator_motors → PWM {pwm_range[0]:g}-{pwm_range[1]:g} µs → "
            f"throttle, {method_hover}, ± sample σ",
            window,
        ),
        thrust_setpoint=thrust_sp,
        px4_hover_thrust=px4_hover,
        battery_voltage_v=voltage,
        air_density_kgpm3=density,
        rotor_speed_radps=speed,
        speed_offset_radps=Estimate(
            full - slope,
            offset_std,
            f"{speed_source} at {voltage:.2f} V on the curve through σ_h and ω(1) = "
            f"{full:.0f} rad/s kept",
            window,
        ),
        speed_slope_radps=slope,
        centre_of_mass_frd_m=_thrust_centre(
            vehicle, commands.mean(axis=1), pwm_range, voltage, slope, full - slope
        ),
        rotor_line=line,
        rotor_line_reason=line_reason,
    )


def _identify_rotor_line(
    log: _Log, windows: tuple[tuple[float, float], ...], vehicle: Vehicle, density: float
) -> tuple[RotorLine | None, str]:
    """The hover rotor speed from the rotors' line in ``sensor_combined`` (module docstring);
    (None, why) when the log cannot show it."""
    data = log.topics.get("sensor_combined")
    if data is None or "accelerometer_m_s2[0]" not in data:
        return None, "no sensor_combined accelerometer in the log"
    accel = np.array([data[f"accelerometer_m_s2[{axis}]"] for axis in range(3)], dtype=float)
    finite = np.isfinite(accel).all(axis=0)
    time_s, accel = data["t"][finite], accel[:, finite]
    if time_s.size < 100:
        return None, f"sensor_combined holds only {time_s.size} finite samples"
    rate = float((time_s.size - 1) / (time_s[-1] - time_s[0]))
    segment = max(8, round(rate))  # 1 Hz resolution
    spectra, weights = [], []
    for start, end in windows:
        inside = (time_s >= start) & (time_s < end)
        if inside.sum() >= segment:
            freqs, power = _accel_psd(accel[:, inside], rate, segment)
            spectra.append(power)
            weights.append(int(inside.sum()))
    if not spectra:
        return None, "no hover window holds a second of sensor_combined"
    power = np.average(spectra, axis=0, weights=weights)
    above = freqs >= ROTOR_LINE_MIN_HZ
    if not above.any():
        return None, f"sensor_combined at {rate:.0f} Hz has no band above {ROTOR_LINE_MIN_HZ:g} Hz"
    peak = float(freqs[above][np.argmax(power[above])])
    line, spread = _weighted_frequency(freqs, power, peak, ROTOR_LINE_BAND)

    correlation, count = _line_against_drive(log, time_s, accel, rate, line)
    if count < FOLD_MIN_WINDOWS:
        return None, (
            f"only {count} airborne {FOLD_WINDOW_S:g} s windows: too few to tell whether "
            f"the line at {line:.1f} Hz is folded"
        )
    if correlation <= -FOLD_MIN_CORRELATION:
        return None, (
            f"the line at {line:.1f} Hz falls as the motors speed up (r = {correlation:.2f}): "
            f"it is folded from above the stream's Nyquist frequency ({rate / 2:.0f} Hz), "
            "where it may sit at several frequencies; a raw IMU log (SDLOG_PROFILE) would show it"
        )
    if correlation < FOLD_MIN_CORRELATION:
        return None, (
            f"the line at {line:.1f} Hz does not follow the motor command × voltage "
            f"(r = {correlation:.2f} over {count} windows): not a rotor line, or folded"
        )
    speed = 2.0 * math.pi * line
    # A harmonic read as the 1× line would turn the rotors faster than the battery can: their
    # shaft power must stay below the electrical power into the motors, where it is logged.
    into_motors = _hover_power_into_motors(log, windows, vehicle.battery.avionics_power_w)
    if into_motors is not None:
        shaft = _shaft_power_w(vehicle, density, speed)
        if shaft > into_motors:
            return None, (
                f"the line at {line:.1f} Hz as the rotors' speed ({speed:.0f} rad/s) needs "
                f"{shaft:.0f} W of shaft power, more than the {into_motors:.0f} W the battery "
                "gives the motors in hover: a harmonic, not the once-per-revolution line"
            )
    span = (windows[0][0], windows[-1][1])
    reference = vehicle.propulsion.reference_air_density_kgpm3
    k_t = (
        vehicle.body.mass_kg * STANDARD_GRAVITY_MPS2 / (ROTOR_COUNT * speed**2)
        * reference / density
    )  # fmt: skip
    method = (
        f"strongest accelerometer line above {ROTOR_LINE_MIN_HZ:g} Hz in hover, in the "
        f"{rate:.0f} Hz stream, ± the rotors' spread; it rises with command × voltage "
        f"(r = {correlation:.2f}, {count} windows): not folded"
    )
    return RotorLine(
        frequency=Estimate(line, spread, method, span),
        correlation=correlation,
        thrust_coefficient=Estimate(
            k_t,
            2.0 * k_t * spread / line,
            f"mg/(4ω_h²) with ω_h = 2π·{line:.1f} Hz = {speed:.0f} rad/s, m = "
            f"{vehicle.body.mass_kg:g} kg, at ρ {reference:g} kg/m³",
            span,
        ),
    ), ""


def _line_against_drive(
    log: _Log, time_s: NDArray, accel: NDArray, rate: float, line_hz: float
) -> tuple[float, int]:
    """Pearson r of the line's frequency (near ``line_hz``) with the mean motor command ×
    voltage, over FOLD_WINDOW_S windows of the airborne span, and the number of windows: a
    line below the stream's Nyquist frequency rises with the rotor speed, a folded one falls."""
    columns = [log.series("actuator_motors", f"control[{m}]", "the rotors' drive")
               for m in range(ROTOR_COUNT)]  # fmt: skip
    t_cmd, command = columns[0][0], np.mean([values for _, values in columns], axis=0)
    if "voltage_v" in log.topics.get("battery_status", {}):
        t_volt, volts = log.series("battery_status", "voltage_v", "the rotors' drive")
    else:  # the command alone orders the rotor speeds when the voltage is not logged
        t_volt, volts = t_cmd, np.ones_like(command)
    short = max(8, round(rate * FOLD_WINDOW_S / 3))
    drive, heard = [], []
    airborne = _airborne_span(log)
    for start in np.arange(airborne[0], airborne[1] - FOLD_WINDOW_S, FOLD_WINDOW_S):
        inside = (time_s >= start) & (time_s < start + FOLD_WINDOW_S)
        commanded = (t_cmd >= start) & (t_cmd < start + FOLD_WINDOW_S)
        if inside.sum() < 2 * short or not commanded.any():
            continue
        freqs, power = _accel_psd(accel[:, inside], rate, short)
        voltage = float(np.interp(start + FOLD_WINDOW_S / 2, t_volt, volts))
        drive.append(float(command[commanded].mean()) * voltage)
        heard.append(_weighted_frequency(freqs, power, line_hz, FOLD_BAND)[0])
    if len(drive) < 2:
        return 0.0, len(drive)
    return float(np.corrcoef(drive, heard)[0, 1]), len(drive)


def _accel_psd(accel: NDArray, rate_hz: float, segment: int) -> tuple[NDArray, NDArray]:
    """Welch PSD of the three accelerometer axes, summed: every axis carries the line."""
    freqs, power = signal.welch(accel, rate_hz, nperseg=min(segment, accel.shape[1]), axis=-1)
    return freqs, power.sum(axis=0)


def _weighted_frequency(
    freqs: NDArray, power: NDArray, centre_hz: float, band: float
) -> tuple[float, float]:
    """Power-weighted mean frequency within ± ``band``·centre of ``centre_hz``, and the
    power-weighted spread about it."""
    near = np.abs(freqs - centre_hz) <= band * centre_hz
    weights = power[near]
    mean = float(np.sum(weights * freqs[near]) / np.sum(weights))
    spread = float(np.sqrt(np.sum(weights * (freqs[near] - mean) ** 2) / np.sum(weights)))
    return mean, spread


# ------------------------------------------------------------------ battery
def _identify_battery(
    log: _Log, hover: HoverIdentification, vehicle: Vehicle
) -> tuple[BatteryIdentification | None, str]:
    """Internal resistance, avionics power and propulsion efficiency (module docstring)."""
    data = log.topics.get("battery_status")
    if data is None:
        return None, "no battery_status in the log"
    missing = [f for f in ("voltage_v", "current_a", "discharged_mah") if f not in data]
    if missing:
        return None, f"battery_status has no {', '.join(missing)}"
    time_s = data["t"]
    volts, amps, used_mah = (np.asarray(data[f], dtype=float)
                             for f in ("voltage_v", "current_a", "discharged_mah"))  # fmt: skip
    armed_from, armed_to, disarm_logged = _armed_span(log)
    use = (time_s >= armed_from) & (time_s < armed_to) & np.isfinite(volts) & (amps > 0)
    if use.sum() < 20:
        return None, f"only {int(use.sum())} battery_status samples while armed with a current"
    design = np.column_stack([np.ones(use.sum()), -used_mah[use], -amps[use]])
    solution, *_ = np.linalg.lstsq(design, volts[use], rcond=None)
    residual = volts[use] - design @ solution
    covariance = np.var(residual, ddof=3) * np.linalg.pinv(design.T @ design)
    span = (float(time_s[use][0]), float(time_s[use][-1]))
    resistance = Estimate(
        float(solution[2]),
        float(np.sqrt(covariance[2, 2])),
        f"V = E₀ − s·Q − R·I, least squares over {int(use.sum())} armed samples "
        f"(RMS residual {np.sqrt(np.mean(residual**2)) * 1e3:.0f} mV)",
        span,
    )
    # after a logged disarm only: the end of the airborne span may still idle the rotors
    after = (time_s >= armed_to + DISARM_SETTLE_S) & np.isfinite(volts) & (amps >= 0)
    avionics = None
    if disarm_logged and after.any():
        power = volts[after] * amps[after]
        avionics = Estimate(
            float(power.mean()),
            float(power.std()),
            f"V·I after the disarm (rotors stopped from {DISARM_SETTLE_S:g} s), {int(after.sum())} "
            "samples ± σ",
            (float(time_s[after][0]), float(time_s[after][-1])),
        )
    efficiency, efficiency_reason = _propulsion_efficiency(
        _mean_in(time_s, volts * amps, hover.windows_s),
        avionics.value if avionics else vehicle.battery.avionics_power_w,
        hover,
        vehicle,
    )
    return BatteryIdentification(resistance, avionics, efficiency, efficiency_reason), ""


def _hover_power_into_motors(
    log: _Log, windows: tuple[tuple[float, float], ...], avionics_w: float
) -> float | None:
    """The battery's mean V·I in the hover windows less the avionics; None when the log
    holds no voltage and current there."""
    battery = log.topics.get("battery_status", {})
    if not {"voltage_v", "current_a"} <= battery.keys():
        return None
    electric = _mean_in(battery["t"], battery["voltage_v"] * battery["current_a"], windows)
    electric = electric[np.isfinite(electric)]
    return float(electric.mean()) - avionics_w if electric.size else None


def _propulsion_efficiency(
    electric_w: NDArray, avionics_w: float, hover: HoverIdentification, vehicle: Vehicle
) -> tuple[Estimate | None, str]:
    """The rotors' shaft power in hover over the battery's power into the motors (its
    samples ``electric_w`` in the hover windows, less the avionics)."""
    if electric_w.size == 0:
        return None, "no battery_status sample in the hover windows"
    into_motors = float(electric_w.mean()) - avionics_w
    shaft = _shaft_power_w(vehicle, hover.air_density_kgpm3, hover.rotor_speed_radps)
    efficiency = shaft / into_motors if into_motors > 0 else math.inf
    if not 0.0 < efficiency <= 1.0:
        return None, (
            f"the rotors' shaft power in hover ({shaft:.0f} W at {hover.rotor_speed_radps:.0f} "
            f"rad/s) against {into_motors:.0f} W into the motors gives an efficiency of "
            f"{efficiency:.2f}: the torque coefficient or the rotor speed is off"
        )
    line = hover.rotor_line
    relative = math.hypot(
        3.0 * line.frequency.relative_uncertainty if line else 0.0,
        float(electric_w.std() / electric_w.mean()) / math.sqrt(electric_w.size),
    )
    return Estimate(
        efficiency,
        efficiency * relative,
        f"shaft 4·k_Q·ω_h³ = {shaft:.0f} W over {into_motors:.0f} W into the motors in hover "
        "(battery V·I less the avionics)",
        (hover.windows_s[0][0], hover.windows_s[-1][1]),
    ), ""


def _shaft_power_w(vehicle: Vehicle, density: float, speed_radps: float) -> float:
    """All rotors' shaft power at ``speed_radps``: 4·k_Q·ω³, k_Q at the air density."""
    prop = vehicle.propulsion
    k_q = prop.torque_coefficient_nm_per_radps2 * density / prop.reference_air_density_kgpm3
    return ROTOR_COUNT * k_q * speed_radps**3


def _armed_span(log: _Log) -> tuple[float, float, bool]:
    """First arm to the disarm after the last armed sample (``actuator_armed``), else the
    airborne span; and whether the span ends at a logged disarm."""
    if "actuator_armed" in log.topics:
        time_s, armed = log.series("actuator_armed", "armed", "")
        if np.any(armed > 0.5):
            on = time_s[armed > 0.5]
            off = time_s[(time_s > on[-1]) & (armed < 0.5)]
            if off.size:
                return float(on[0]), float(off[0]), True
            return float(on[0]), float(time_s[-1]), False
    return (*_airborne_span(log), False)


def _thrust_centre(
    vehicle: Vehicle,
    command: NDArray,
    pwm_range: tuple[float, float],
    voltage_v: float,
    slope: float,
    offset: float,
) -> tuple[float, float]:
    """The body (x, y) about which the rotors' thrusts at ``command`` balance: in a steady
    hover the centre of mass (the rotors' yaw torques aside). Thrust ∝ ω², ω on the
    identified speed curve (quad_model.dynamics)."""
    prop = vehicle.propulsion
    throttle = pwm_to_throttle(pwm_range[0] + (pwm_range[1] - pwm_range[0]) * command)
    speed = (slope * throttle + offset) * voltage_v / prop.speed_curve_voltage_v
    share = speed**2 / np.sum(speed**2)
    hubs = np.array(prop.position_frd_m)[:, :2]
    centre = share @ hubs - hubs.mean(axis=0)
    return float(centre[0]), float(centre[1])


# ------------------------------------------------------------------ torque per unit
def torque_per_unit_nm(
    vehicle: Vehicle,
    log_params: Mapping[str, float],
    hover_command: float,
    pwm_range_us: tuple[float, float],
    voltage_v: float,
    air_density_kgpm3: float,
) -> NDArray[np.float64]:
    """Body moment (N·m, roll/pitch/yaw) per unit of PX4's normalized torque set-point at
    hover, through the reference autopilot's mixer and the model on its thrust stand.

    The stand is powered from an ideal supply at ``voltage_v`` (the log's hover voltage) so
    the speed curve is evaluated where the hover was; the moment, which is ∝ ρ at fixed rotor
    speeds, is scaled from the stand's air to ``air_density_kgpm3``.
    """
    # the log's quad geometry; the reference autopilot's defaults for what it lacks
    overrides = {k: float(v) for k, v in log_params.items() if _GEOMETRY_PARAM.fullmatch(k)}
    allocator = ControlAllocator(Parameters(overrides))
    battery = vehicle.battery
    bench = replace(
        vehicle,
        battery=replace(
            battery,
            cell_full_v=voltage_v / battery.cell_count,
            cell_empty_v=min(battery.cell_empty_v, 0.5 * voltage_v / battery.cell_count),
            internal_resistance_ohm=0.0,
        ),
    )
    stand = QuadModel(bench, np.random.default_rng(0), mount=Mount.THRUST_STAND)
    settle_s = SETTLE_TIME_CONSTANTS * vehicle.propulsion.motor_time_constant_s
    per_unit = np.zeros(3)
    for axis in range(3):
        moments = []
        for sign in (1.0, -1.0):
            torque = np.zeros(3)
            torque[axis] = sign * TORQUE_STEP
            command = allocator.allocate(torque, hover_command)
            pwm = pwm_range_us[0] + (pwm_range_us[1] - pwm_range_us[0]) * command
            stand.reset()
            stand.advance(pwm_to_throttle(pwm), settle_s)
            moments.append(stand.truth.moment_frd_nm[axis])
        density_ratio = air_density_kgpm3 / stand.truth.air_density_kgpm3
        per_unit[axis] = (moments[0] - moments[1]) / (2 * TORQUE_STEP) * density_ratio
    return per_unit


# ------------------------------------------------------------------ rate-loop plant
def plant_response(
    freqs_hz: NDArray, gain_radps2: float, tau_s: float, delay_s: float, gyro_cutoff_hz: float
) -> NDArray[np.complex128]:
    """B·e^{−sd}/(s(τs+1)) times PX4's 2nd-order Butterworth gyro low-pass.

    The low-pass is the analog prototype: PX4's ``LowPassFilter2p`` is its bilinear transform
    pre-warped at the cutoff, so the two agree within a fraction of a degree below 25 Hz at
    PX4's 400-1000 Hz gyro rates. A cutoff of 0 means no filter, as in PX4.
    """
    s = 2j * np.pi * np.asarray(freqs_hz)
    response = gain_radps2 * np.exp(-s * delay_s) / (s * (tau_s * s + 1.0))
    if gyro_cutoff_hz > 0:
        b, a = signal.butter(2, 2 * np.pi * gyro_cutoff_hz, analog=True)
        response = response * signal.freqs(b, a, 2 * np.pi * np.asarray(freqs_hz))[1]
    return response


@dataclass(frozen=True)
class _PlantFit:
    gain: float
    tau: float
    delay: float
    std: NDArray[np.float64]  # of log(B), τ, d
    band_hz: tuple[float, float]
    points: int


def _fit_plant(
    log: _Log, axis: int, window: tuple[float, float], rate_hz: float, cutoff_hz: float
) -> _PlantFit | str:
    """Joint input-output response on ``window`` and its least-squares fit, or the reason
    the axis cannot be fitted."""
    grid = np.arange(window[0], window[1], 1.0 / rate_hz)
    signals = {}
    for name, topic, field in (
        ("torque", "vehicle_torque_setpoint", f"xyz[{axis}]"),
        ("rate", "vehicle_angular_velocity", f"xyz[{axis}]"),
        ("rate_sp", "vehicle_rates_setpoint", _AXES[axis]),
    ):
        t, v = log.series(topic, field, "rate-loop fit")
        signals[name] = np.interp(grid, t, v)
    record_s = grid.size / rate_hz
    # the longest of default_windows is record/5 and must hold 2 periods of f_a (+5 %)
    band = (10.5 / record_s, BAND_TOP_FRACTION * rate_hz)
    freqs = log_grid(band, GRID_POINTS)
    windows = default_windows(record_s, band)
    try:
        instrument = signals["rate_sp"]
        to_rate = estimate_response(instrument, signals["rate"], rate_hz, freqs, windows)
        to_torque = estimate_response(instrument, signals["torque"], rate_hz, freqs, windows)
    except CredibilityError as error:
        return f"no response: {error}"
    response = to_rate.complex_response / to_torque.complex_response
    coherence = np.minimum(to_rate.coherence, to_torque.coherence)
    keep = coherence >= COHERENCE_MIN
    if keep.sum() < MIN_FIT_POINTS:
        return (
            f"only {keep.sum()} of {GRID_POINTS} frequencies reach coherence "
            f"{COHERENCE_MIN} on both legs (need {MIN_FIT_POINTS})"
        )
    f, h = freqs[keep], response[keep]
    weight = coherence_weight(coherence[keep])  # squared in the cost: CIFER's W_γ²

    def residuals(p: NDArray) -> NDArray:
        ratio = h / plant_response(f, math.exp(p[0]), p[1], p[2], cutoff_hz)
        log_ratio = np.log(ratio)  # real part: log-magnitude error, imaginary: phase (rad)
        return np.concatenate((weight * log_ratio.real, weight * log_ratio.imag))

    # start: B from the lowest gated point as a pure integrator, mid-range lags
    start = [math.log(abs(h[0]) * 2 * np.pi * f[0]), 0.02, 0.01]
    bounds = (
        [-np.inf, TAU_BOUNDS_S[0], DELAY_BOUNDS_S[0]],
        [np.inf, TAU_BOUNDS_S[1], DELAY_BOUNDS_S[1]],
    )
    fit = optimize.least_squares(residuals, start, bounds=bounds)
    dof = max(2 * f.size - 3, 1)
    covariance = np.linalg.pinv(fit.jac.T @ fit.jac) * (2.0 * fit.cost / dof)
    return _PlantFit(
        math.exp(fit.x[0]),
        float(fit.x[1]),
        float(fit.x[2]),
        np.sqrt(np.diag(covariance)),
        (float(f[0]), float(f[-1])),
        int(f.size),
    )


def _identify_axis(
    log: _Log,
    axis: int,
    window: tuple[float, float],
    airborne: tuple[float, float],
    rate_hz: float,
    cutoff_hz: float,
    torque_per_unit: float,
) -> AxisIdentification:
    name = _AXES[axis]
    fit = _fit_plant(log, axis, window, rate_hz, cutoff_hz)
    if isinstance(fit, str):
        return AxisIdentification(name, identified=False, reason=fit)
    cross = _fit_plant(log, axis, airborne, rate_hz, cutoff_hz)
    cross_gain = None if isinstance(cross, str) else cross.gain
    # the larger of the fit's own σ and the disagreement with the whole-flight fit, and for a
    # slow log the aliasing bias bound, in quadrature
    random_spread = max(fit.gain * fit.std[0], abs(fit.gain - (cross_gain or fit.gain)))
    aliasing = ALIASING_BIAS if rate_hz < ALIASING_RATE_HZ else 0.0
    gain_spread = math.hypot(random_spread, aliasing * fit.gain)
    method = (
        f"rate_sp-instrumented torque_sp→rate fit, {fit.points} pts "
        f"{fit.band_hz[0]:.2g}-{fit.band_hz[1]:.2g} Hz, ± max(fit σ, whole-flight Δ)"
        + (f" ⊕ {aliasing:.0%} aliasing" if aliasing else "")
    )
    inertia = torque_per_unit / fit.gain
    problems = []
    if cross_gain is None:
        problems.append(f"whole-flight cross-check failed ({cross})")
    if gain_spread > MAX_RELATIVE_UNCERTAINTY * fit.gain:
        problems.append(
            f"B uncertain by {gain_spread / fit.gain:.0%} (> {MAX_RELATIVE_UNCERTAINTY:.0%})"
        )
    lag_identified = (
        not problems and fit.std[1] < 0.5 * fit.tau and TAU_BOUNDS_S[0] < fit.tau < TAU_BOUNDS_S[1]
    )
    if not lag_identified:
        problems.append("τ_m not identifiable (B unreliable, τ at its bound or σ > τ/2)")
    lag_method = f"same fit, ± fit σ{'' if lag_identified else ' (NOT identifiable)'}"
    return AxisIdentification(
        name,
        identified=True,
        reliable=cross_gain is not None and gain_spread <= MAX_RELATIVE_UNCERTAINTY * fit.gain,
        reason="; ".join(problems),
        band_hz=fit.band_hz,
        fit_points=fit.points,
        control_effectiveness_radps2=Estimate(fit.gain, gain_spread, method, window),
        motor_time_constant_s=Estimate(fit.tau, fit.std[1], lag_method, window),
        motor_lag_identified=lag_identified,
        delay_s=Estimate(fit.delay, fit.std[2], lag_method, window),
        torque_per_unit_nm=float(torque_per_unit),
        inertia_kgm2=Estimate(
            inertia,
            inertia * gain_spread / fit.gain,
            f"I = {torque_per_unit:.3g} N·m/unit (mixer + thrust stand) / B; B: {method}",
            window,
        ),
        cross_check_inertia_kgm2=None if cross_gain is None else torque_per_unit / cross_gain,
    )


# ------------------------------------------------------------------ presentation
def vehicle_name_for_log(log_path: str | Path) -> str:
    """The bundled vehicle of the log's airframe (``SYS_AUTOSTART``, as ``rig replay``)."""
    log = _read_log(Path(log_path))
    autostart = log.params.get("SYS_AUTOSTART")
    if autostart is None or int(autostart) not in AIRFRAMES:
        known = ", ".join(f"{k} {v}" for k, v in AIRFRAMES.items())
        raise IdentificationError(
            f"{log.path}: SYS_AUTOSTART = {autostart} has no bundled vehicle (known: {known}); "
            "give --vehicle NAME|PATH"
        )
    return AIRFRAMES[int(autostart)]


def _format(estimate: Estimate | None, scale: float = 1.0, digits: int = 4) -> str:
    if estimate is None:
        return "—"
    value, sigma = estimate.value * scale, estimate.uncertainty * scale
    return f"{value:.{digits}g} ± {sigma:.2g}"


def identification_table(result: Identification) -> Table:
    """The result as a rich table: quantity, value ± uncertainty, method, window."""
    table = Table(title=f"{result.log.name}: {result.vehicle_name}", title_justify="left")
    for column in ("quantity", "value", "method", "window"):
        table.add_column(column, overflow="fold")
    hover = result.hover

    def add(name: str, estimate: Estimate | None, text: str | None = None) -> None:
        window = f"{estimate.window_s[0]:.1f}-{estimate.window_s[1]:.1f} s" if estimate else ""
        table.add_row(name, text or _format(estimate), estimate.method if estimate else "", window)

    hover_spans = ", ".join(f"{a:.1f}-{b:.1f}" for a, b in hover.windows_s)
    table.add_row("hover windows", f"{hover_spans} s", "airborne, small |v| and rates", "")
    table.add_row(
        "motor commands",
        " ".join(f"{u:.3f}" for u in hover.motor_command),
        "mean actuator_motors per motor",
        "",
    )
    add("hover throttle", hover.throttle)
    px4 = "—" if hover.px4_hover_thrust is None else f"{hover.px4_hover_thrust:.3f}"
    table.add_row(
        "thrust sp / PX4 hover est.",
        f"{hover.thrust_setpoint:.3f} / {px4}",
        "vehicle_thrust_setpoint / hover_thrust_estimate",
        "",
    )
    line = hover.rotor_line
    if line is None:
        table.add_row("rotor line", "not identified", hover.rotor_line_reason, "")
        table.add_row(
            "hover rotor speed",
            f"{hover.rotor_speed_radps:.0f} rad/s",
            f"√(mg/4k_T) at ρ {hover.air_density_kgpm3:.3f} kg/m³, {hover.battery_voltage_v:.2f} V",
            "",
        )
    else:
        add("rotor line Hz", line.frequency)
        speed = f"{hover.rotor_speed_radps:.0f} rad/s"
        table.add_row("hover rotor speed", speed, "2π × the line", "")
        add("thrust_coefficient", line.thrust_coefficient)
    add("speed_offset_radps", hover.speed_offset_radps)
    table.add_row(
        "speed_slope_radps",
        f"{hover.speed_slope_radps:.1f}",
        "ω(1) of the vehicle kept: slope = ω(1) − offset",
        "",
    )
    for axis in result.axes:
        if not axis.identified:
            table.add_row(f"{axis.axis}", "not identified", axis.reason, "")
            continue
        verdict = "" if axis.reliable else " (unreliable)"
        add(f"{axis.axis} B rad/s²{verdict}", axis.control_effectiveness_radps2)
        add(f"{axis.axis} inertia kg·m²{verdict}", axis.inertia_kgm2)
        cross = axis.cross_check_inertia_kgm2
        cross_text = "—" if cross is None else f"{cross:.4g}"
        table.add_row(f"{axis.axis} inertia, whole flight", cross_text, "cross-check window", "")
        add(f"{axis.axis} τ_m s", axis.motor_time_constant_s)
        add(f"{axis.axis} delay s", axis.delay_s)
        if axis.reason:
            table.add_row("", "", axis.reason, "")
    battery = result.battery
    if battery is None:
        table.add_row("battery", "not identified", result.battery_reason, "")
    else:
        add("internal_resistance_ohm", battery.internal_resistance_ohm)
        add("avionics_power_w", battery.avionics_power_w)
        if battery.propulsion_efficiency is None:
            table.add_row("propulsion_efficiency", "not identified", battery.efficiency_reason, "")
        else:
            add("propulsion_efficiency", battery.propulsion_efficiency)
    for note in result.notes:
        table.add_row("note", "", note, "")
    return table


def identification_toml(result: Identification, vehicle: Vehicle) -> str:
    """``[body]``/``[propulsion]`` lines to paste into the vehicle file, each tagged with its
    method and window; values the log could not identify are kept from ``vehicle`` and say so."""
    hover, prop = result.hover, vehicle.propulsion
    source = f"rig identify {result.log.name}"
    inertia = np.array(vehicle.body.inertia_kgm2)
    tags = []
    for index, axis in enumerate(result.axes):
        estimate = axis.inertia_kgm2
        if axis.reliable and estimate is not None:
            inertia[index, index] = estimate.value
            tags.append(f"I_{'xyz'[index] * 2} [identified] {_format(estimate, digits=3)}")
        else:
            tags.append(f"I_{'xyz'[index] * 2} kept ({axis.reason.split(';')[0]})")
    window = hover.speed_offset_radps.window_s
    offset = hover.speed_offset_radps
    hubs = np.array(prop.position_frd_m)
    centre = np.array([*hover.centre_of_mass_frd_m, 0.0])
    positions = hubs - np.append(hubs[:, :2].mean(axis=0), 0.0) - centre
    lines = [
        "[body]",
        f"# {source}: " + "; ".join(tags),
        f"inertia_kgm2 = {[[round(float(v), 5) for v in row] for row in inertia]}",
        "",
        "[propulsion]",
        f"# {source}: the hover motors balance about x {centre[0] * 1e3:+.1f} mm, "
        f"y {centre[1] * 1e3:+.1f} mm from the rotors' centre (the centre of mass)",
        f"position_frd_m = {[[round(float(v), 4) for v in row] for row in positions]}",
        f"speed_slope_radps = {hover.speed_slope_radps:.1f}   # [identified] {source}, "
        f"ω(1) = {prop.speed_slope_radps + prop.speed_offset_radps:.0f} rad/s kept",
        f"speed_offset_radps = {offset.value:.1f}   # [identified] {source}, hover "
        f"{window[0]:.1f}-{window[1]:.1f} s, ± {offset.uncertainty:.0f} rad/s",
    ]
    line = hover.rotor_line
    if line is None:
        lines.append(f"# thrust_coefficient_n_per_radps2 kept: {hover.rotor_line_reason}")
    else:
        k_t = line.thrust_coefficient
        lines.append(
            f"thrust_coefficient_n_per_radps2 = {k_t.value:.4g}   # [identified] {source}, "
            f"hover rotor line {line.frequency.value:.1f} ± {line.frequency.uncertainty:.1f} Hz"
        )
    lags = [a.motor_time_constant_s for a in result.axes if a.motor_lag_identified]
    if lags:
        tau = float(np.mean([e.value for e in lags]))
        lines.append(
            f"motor_time_constant_s = {tau:.4f}   # [identified] {source}, mean of {len(lags)} axes"
        )
    else:
        lines.append(
            f"# motor_time_constant_s = {prop.motor_time_constant_s} kept: "
            "not identifiable from this log"
        )
    battery = result.battery
    lines += ["", "[battery]"]
    if battery is None:
        lines.append(f"# kept: {result.battery_reason}")
    else:
        for key, estimate, digits, why in (
            ("internal_resistance_ohm", battery.internal_resistance_ohm, 4, ""),
            ("avionics_power_w", battery.avionics_power_w, 3, "no current after the disarm"),
            ("propulsion_efficiency", battery.propulsion_efficiency, 3, battery.efficiency_reason),
        ):
            if estimate is None:
                lines.append(f"# {key} kept: {why}")
            else:
                lines.append(
                    f"{key} = {estimate.value:.{digits}g}   # [identified] {source}, "
                    f"± {estimate.uncertainty:.2g}"
                )
    return "\n".join(lines) + "\n"
