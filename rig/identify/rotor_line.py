"""The rotors' once-per-revolution line in the accelerometer's spectrum: the hover rotor speed
where the log shows it, checked against folding and against the power into the motors."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from px4_logs import FlightLog
from quad_model.vehicle import Vehicle
from rig.identify.bounds import QUAD_ROTORS
from rig.identify.power import hover_power_into_motors, hover_thrust_coefficient, shaft_power_w
from rig.identify.results import Estimate, RotorLine

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


def identify_rotor_line(
    log: FlightLog, windows: tuple[tuple[float, float], ...], vehicle: Vehicle, density: float
) -> tuple[RotorLine | None, str]:
    """The hover rotor speed from the rotors' line in ``sensor_combined`` (:mod:`rig.identify`);
    (None, why) when the log cannot show it."""
    data = log.topics.get("sensor_combined")
    if data is None or "accelerometer_m_s2[0]" not in data:
        return None, "no sensor_combined accelerometer in the log"
    accel = np.array([data[f"accelerometer_m_s2[{axis}]"] for axis in range(3)], dtype=float)
    finite = np.isfinite(accel).all(axis=0)
    time_s, accel = log.time_s("sensor_combined")[finite], accel[:, finite]
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
    into_motors = hover_power_into_motors(log, windows, vehicle.battery.avionics_power_w)
    if into_motors is not None:
        shaft = shaft_power_w(vehicle, density, speed)
        if shaft > into_motors:
            return None, (
                f"the line at {line:.1f} Hz as the rotors' speed ({speed:.0f} rad/s) needs "
                f"{shaft:.0f} W of shaft power, more than the {into_motors:.0f} W the battery "
                "gives the motors in hover: a harmonic, not the once-per-revolution line"
            )
    span = (windows[0][0], windows[-1][1])
    reference = vehicle.propulsion.reference_air_density_kgpm3
    k_t = hover_thrust_coefficient(vehicle, speed, density)
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
    log: FlightLog, time_s: NDArray, accel: NDArray, rate: float, line_hz: float
) -> tuple[float, int]:
    """Pearson r of the line's frequency (near ``line_hz``) with the mean motor command ×
    voltage, over FOLD_WINDOW_S windows of the airborne span, and the number of windows: a
    line below the stream's Nyquist frequency rises with the rotor speed, a folded one falls."""
    columns = [log.series("actuator_motors", f"control[{m}]", "the rotors' drive")
               for m in range(QUAD_ROTORS)]  # fmt: skip
    t_cmd, command = columns[0][0], np.mean([values for _, values in columns], axis=0)
    if "voltage_v" in log.topics.get("battery_status", {}):
        t_volt, volts = log.series("battery_status", "voltage_v", "the rotors' drive")
    else:  # the command alone orders the rotor speeds when the voltage is not logged
        t_volt, volts = t_cmd, np.ones_like(command)
    short = max(8, round(rate * FOLD_WINDOW_S / 3))
    drive, heard = [], []
    airborne = log.airborne_span()
    for start in np.arange(airborne[0], airborne[1] - FOLD_WINDOW_S, FOLD_WINDOW_S):
        inside = (time_s >= start) & (time_s < start + FOLD_WINDOW_S)
        commanded = (t_cmd >= start) & (t_cmd < start + FOLD_WINDOW_S)
        if inside.sum() < 2 * short or not commanded.any():
            continue
        freqs, power = _accel_psd(accel[:, inside], rate, short)
        voltage = float(np.interp(start + FOLD_WINDOW_S / 2, t_volt, volts))
        drive.append(float(command[commanded].mean()) * voltage)
        heard.append(_weighted_frequency(freqs, power, line_hz, FOLD_BAND)[0])
    if len(drive) < 2 or np.ptp(drive) == 0.0 or np.ptp(heard) == 0.0:  # r undefined
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
