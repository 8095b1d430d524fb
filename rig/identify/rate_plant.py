"""The rate-loop plant per axis (torque set-point to body rate, closed-loop data with the
rate set-point as instrument) and the inertia it gives with the torque per unit command."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, signal

from credibility.errors import CredibilityError
from credibility.indices import coherence_weight
from credibility.spectral import default_windows, estimate_response, log_grid
from px4_logs import FlightLog
from quad_model.frames import pwm_to_throttle
from quad_model.model import Mount, QuadModel
from quad_model.vehicle import Vehicle
from rig.autopilots.reference.control import ControlAllocator
from rig.autopilots.reference.params import Parameters
from rig.identify.bounds import QUAD_ROTORS, bounded, refusal
from rig.identify.results import AXES, MAX_RELATIVE_UNCERTAINTY, AxisIdentification, Estimate

#: Below this log rate the rate loop's torque noise (D term) folds into the analysis band and
#: biases B low, by how much depends on that noise; ALIASING_BIAS bounds it (rig flights
#: resampled to 50 Hz read B 1-20 % low, tests/rig/test_identify.py) and enters B's uncertainty.
ALIASING_RATE_HZ = 100.0
ALIASING_BIAS = 0.25
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


#: Fit bounds: τ_m and d between 1 ms and 0.2 s cover hobby to heavy-lift propulsion.
TAU_BOUNDS_S = (1e-3, 0.2)


DELAY_BOUNDS_S = (0.0, 0.2)


#: Torque set-point step for the numerical derivative through mixer and thrust stand
#: (small: no motor saturates around hover).
TORQUE_STEP = 0.05


#: Thrust-stand settling time in motor time constants (e^-20: settled to 2e-9).
SETTLE_TIME_CONSTANTS = 20.0


_GEOMETRY_PARAM = re.compile(rf"CA_ROTOR[0-{QUAD_ROTORS - 1}]_(PX|PY|KM)")


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
    log: FlightLog, axis: int, window: tuple[float, float], rate_hz: float, cutoff_hz: float
) -> _PlantFit | str:
    """Joint input-output response on ``window`` and its least-squares fit, or the reason
    the axis cannot be fitted."""
    grid = np.arange(window[0], window[1], 1.0 / rate_hz)
    signals = {}
    for name, topic, field in (
        ("torque", "vehicle_torque_setpoint", f"xyz[{axis}]"),
        ("rate", "vehicle_angular_velocity", f"xyz[{axis}]"),
        ("rate_sp", "vehicle_rates_setpoint", AXES[axis]),
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
    # '2-point' differences of a dense residual: a dense Jacobian, never sparse or an operator
    assert isinstance(fit.jac, np.ndarray)
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


def identify_axis(
    log: FlightLog,
    axis: int,
    window: tuple[float, float],
    airborne: tuple[float, float],
    rate_hz: float,
    cutoff_hz: float,
    torque_per_unit: float,
) -> AxisIdentification:
    name = AXES[axis]
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
        control_effectiveness_radps2=bounded(
            "control effectiveness", Estimate(fit.gain, gain_spread, method, window)
        ),
        motor_time_constant_s=bounded(
            "motor time constant", Estimate(fit.tau, fit.std[1], lag_method, window)
        ),
        motor_lag_identified=lag_identified,
        delay_s=bounded("delay", Estimate(fit.delay, fit.std[2], lag_method, window)),
        torque_per_unit_nm=float(torque_per_unit),
        inertia_kgm2=bounded(
            "inertia",
            Estimate(
                inertia,
                inertia * gain_spread / fit.gain,
                f"I = {torque_per_unit:.3g} N·m/unit (mixer + thrust stand) / B; B: {method}",
                window,
            ),
        ),
        cross_check_inertia_kgm2=_possible_inertia(torque_per_unit, cross_gain),
    )


def _possible_inertia(torque_per_unit: float, gain: float | None) -> float | None:
    """The cross-check's inertia, None without a fit or outside the inertia's bound."""
    if gain is None or refusal("inertia", torque_per_unit / gain):
        return None
    return torque_per_unit / gain
