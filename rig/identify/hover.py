"""The hover: its throttle on the speed curve, the centre of thrust, the hover rotor speed
(measured by the ESCs, else heard as the rotor line, else from the vehicle's k_T)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from px4_logs import FlightLog, MotorOutputs
from px4_logs.flight_log import HOVER_MAX_RATE_RADPS, HOVER_MAX_SPEED_MPS, MIN_HOVER_S
from quad_model.frames import STANDARD_GRAVITY_MPS2, pwm_to_throttle
from quad_model.vehicle import Vehicle
from rig.identify.bounds import QUAD_ROTORS, bounded, motor_refusal
from rig.identify.power import hover_thrust_coefficient, mean_in
from rig.identify.results import Estimate, HoverIdentification, IdentificationError
from rig.identify.rotor_line import identify_rotor_line


def identify_hover(log: FlightLog, vehicle: Vehicle, outputs: MotorOutputs) -> HoverIdentification:
    pwm_range = outputs.pwm_range_us
    windows = log.hover_windows()
    if not windows:
        raise IdentificationError(
            f"{log.path}: no hover window found (airborne, RMS |v| ≤ {HOVER_MAX_SPEED_MPS} m/s "
            f"and |rates| ≤ {HOVER_MAX_RATE_RADPS} rad/s for ≥ {MIN_HOVER_S:g} s)"
        )
    span = (windows[0][0], windows[-1][1])
    per_motor = []
    for motor in range(QUAD_ROTORS):
        t, u = log.series("actuator_motors", f"control[{motor}]", "hover motor commands")
        per_motor.append(mean_in(t, u, windows))
    commands = np.array(per_motor)  # motors × samples
    pwm = pwm_range[0] + (pwm_range[1] - pwm_range[0]) * commands
    throttle_samples = pwm_to_throttle(pwm).mean(axis=0)
    throttle = float(throttle_samples.mean())
    t, thrust_z = log.series("vehicle_thrust_setpoint", "xyz[2]", "hover thrust")
    thrust_sp = -float(mean_in(t, thrust_z, windows).mean())
    px4_hover = None
    if "hover_thrust_estimate" in log.topics:
        t, h = log.series("hover_thrust_estimate", "hover_thrust", "")
        in_hover = mean_in(t, h, windows)
        px4_hover = float(in_hover.mean()) if in_hover.size else None
    t, volts = log.series("battery_status", "voltage_v", "the speed curve needs the voltage")
    voltage = float(mean_in(t, volts, windows).mean())
    prop = vehicle.propulsion
    if "vehicle_air_data" in log.topics:
        t, rho = log.series("vehicle_air_data", "rho", "")
        density = float(mean_in(t, rho, windows).mean())
        density_source = "vehicle_air_data.rho"
    else:
        density = prop.reference_air_density_kgpm3
        density_source = "the vehicle's reference density (log has no vehicle_air_data)"
    line, line_reason = identify_rotor_line(log, windows, vehicle, density)
    measured, measured_reason = _measured_speed(log, windows)
    thrust_coefficient = None
    if measured is not None and not measured.refused:
        speed, speed_std = measured.value, measured.uncertainty
        speed_source = f"ω_h = {speed:.0f} rad/s (measured by the ESCs)"
        thrust_coefficient = bounded(
            "thrust coefficient",
            Estimate(
                hover_thrust_coefficient(vehicle, speed, density),
                2.0 * hover_thrust_coefficient(vehicle, speed, density) * speed_std / speed,
                f"mg/(4ω_h²) with ω_h = {speed:.0f} rad/s measured by the ESCs (esc_status), "
                f"m = {vehicle.body.mass_kg:g} kg, at ρ {prop.reference_air_density_kgpm3:g} kg/m³",
                measured.window_s,
            ),
        )
    elif line is not None:
        speed = 2.0 * math.pi * line.frequency.value
        speed_std = 2.0 * math.pi * line.frequency.uncertainty
        speed_source = f"ω_h = {speed:.0f} rad/s (the rotor line)"
        thrust_coefficient = line.thrust_coefficient
    else:
        k_t = prop.thrust_coefficient_n_per_radps2 * density / prop.reference_air_density_kgpm3
        speed = math.sqrt(vehicle.body.mass_kg * STANDARD_GRAVITY_MPS2 / (QUAD_ROTORS * k_t))
        speed_std = 0.0
        speed_source = f"ω_h = √(mg/4k_T) = {speed:.0f} rad/s (ρ from {density_source})"
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
    motor_command = tuple(float(c.mean()) for c in commands)
    low, high = outputs.output_range
    throttle_estimate = bounded(
        "hover throttle",
        Estimate(
            throttle,
            throttle_std,
            f"actuator_motors → {outputs.protocol.name} {low:g}-{high:g} {outputs.unit} → "
            f"throttle, {method_hover}, ± sample σ",
            window,
            motor_refusal(motor_command),
        ),
    )
    offset_estimate = Estimate(
        full - slope,
        offset_std,
        f"{speed_source} at {voltage:.2f} V on the curve through σ_h and ω(1) = "
        f"{full:.0f} rad/s kept",
        window,
        throttle_estimate.refused
        and f"the hover throttle is refused ({throttle_estimate.refused})",
    )
    return HoverIdentification(
        windows_s=windows,
        motor_command=motor_command,
        throttle=throttle_estimate,
        thrust_setpoint=thrust_sp,
        px4_hover_thrust=px4_hover,
        battery_voltage_v=voltage,
        air_density_kgpm3=density,
        rotor_speed_radps=speed,
        speed_offset_radps=bounded("speed offset", offset_estimate),
        speed_slope_radps=slope,
        centre_of_mass_frd_m=_thrust_centre(
            vehicle, commands.mean(axis=1), pwm_range, voltage, slope, full - slope
        ),
        rotor_line=line,
        rotor_line_reason=line_reason,
        measured_rotor_speed=measured,
        measured_speed_reason=measured_reason,
        thrust_coefficient=thrust_coefficient,
    )


def _measured_speed(
    log: FlightLog, windows: tuple[tuple[float, float], ...]
) -> tuple[Estimate | None, str]:
    """ω_h as the ESCs report it (``esc_status``), mean of the motors ± their spread; (None,
    why) when the log holds no speeds in the hover windows."""
    logged = log.rotor_speeds()
    if logged is None:
        return None, "no esc_status rotor speeds in the log"
    time_s, speeds = logged
    inside = [mean_in(time_s, column, windows) for column in speeds.T]
    if any(samples.size == 0 for samples in inside):
        return None, "esc_status holds no sample in the hover windows"
    per_motor = np.array([samples.mean() for samples in inside])
    estimate = Estimate(
        float(per_motor.mean()),
        float(per_motor.std()),
        f"esc_status esc_rpm in hover, mean of {per_motor.size} motors "
        f"({', '.join(f'{w:.0f}' for w in per_motor)} rad/s) ± their spread",
        (windows[0][0], windows[-1][1]),
    )
    return bounded("rotor speed", estimate), ""


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
