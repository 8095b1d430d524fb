"""An identification as a terminal table and as lines for a vehicle file."""

from __future__ import annotations

import numpy as np
from rich.table import Table

from quad_model.vehicle import Vehicle
from rig.identify.bounds import motor_refusal
from rig.identify.results import Estimate, Identification


def format_estimate(estimate: Estimate | None, scale: float = 1.0, digits: int = 4) -> str:
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
        if estimate is not None and estimate.refused:
            table.add_row(name, "refused", estimate.refused, window)
            return
        table.add_row(
            name, text or format_estimate(estimate), estimate.method if estimate else "", window
        )

    hover_spans = ", ".join(f"{a:.1f}-{b:.1f}" for a, b in hover.windows_s)
    table.add_row("hover windows", f"{hover_spans} s", "airborne, small |v| and rates", "")
    impossible = motor_refusal(hover.motor_command)
    table.add_row(
        "motor commands",
        "refused" if impossible else " ".join(f"{u:.3f}" for u in hover.motor_command),
        impossible or "mean actuator_motors per motor",
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
    line, measured = hover.rotor_line, hover.measured_rotor_speed
    if measured is not None:
        add("hover rotor speed rad/s", measured)
    if line is None:
        table.add_row("rotor line", "not identified", hover.rotor_line_reason, "")
    else:
        add("rotor line Hz", line.frequency)
    speed = f"{hover.rotor_speed_radps:.0f} rad/s"
    if (measured is None or measured.refused) and line is None:
        table.add_row(
            "hover rotor speed",
            speed,
            f"√(mg/4k_T) at ρ {hover.air_density_kgpm3:.3f} kg/m³, {hover.battery_voltage_v:.2f} V",
            "",
        )
    elif measured is None or measured.refused:
        table.add_row("hover rotor speed", speed, "2π × the line", "")
    if hover.thrust_coefficient is not None:
        add("thrust_coefficient", hover.thrust_coefficient)
    add("speed_offset_radps", hover.speed_offset_radps)
    offset_refused = hover.speed_offset_radps.refused
    table.add_row(
        "speed_slope_radps",
        "refused" if offset_refused else f"{hover.speed_slope_radps:.1f}",
        offset_refused or "ω(1) of the vehicle kept: slope = ω(1) − offset",
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
        if axis.reliable and estimate is not None and not estimate.refused:
            inertia[index, index] = estimate.value
            tags.append(f"I_{'xyz'[index] * 2} [identified] {format_estimate(estimate, digits=3)}")
        else:
            why = estimate.refused if estimate and estimate.refused else axis.reason.split(";")[0]
            tags.append(f"I_{'xyz'[index] * 2} kept ({why})")
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
    ]
    if hover.throttle.refused:
        lines.append(
            f"# position_frd_m kept: the hover throttle is refused ({hover.throttle.refused})"
        )
    else:
        lines += [
            f"# {source}: the hover motors balance about x {centre[0] * 1e3:+.1f} mm, "
            f"y {centre[1] * 1e3:+.1f} mm from the rotors' centre (the centre of mass)",
            f"position_frd_m = {[[round(float(v), 4) for v in row] for row in positions]}",
        ]
    if offset.refused:
        lines.append(f"# speed_slope_radps, speed_offset_radps kept: {offset.refused}")
    else:
        lines += [
            f"speed_slope_radps = {hover.speed_slope_radps:.1f}   # [identified] {source}, "
            f"ω(1) = {prop.speed_slope_radps + prop.speed_offset_radps:.0f} rad/s kept",
            f"speed_offset_radps = {offset.value:.1f}   # [identified] {source}, hover "
            f"{window[0]:.1f}-{window[1]:.1f} s, ± {offset.uncertainty:.0f} rad/s",
        ]
    lines.append(_thrust_coefficient_line(result, source))
    lags = [
        a.motor_time_constant_s
        for a in result.axes
        if a.motor_lag_identified
        and a.motor_time_constant_s is not None  # identified: estimated
        and not a.motor_time_constant_s.refused
    ]
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
            if estimate is None or estimate.refused:
                lines.append(f"# {key} kept: {estimate.refused if estimate else why}")
            else:
                lines.append(
                    f"{key} = {estimate.value:.{digits}g}   # [identified] {source}, "
                    f"± {estimate.uncertainty:.2g}"
                )
    return "\n".join(lines) + "\n"


def _thrust_coefficient_line(result: Identification, source: str) -> str:
    hover = result.hover
    k_t, line, measured = hover.thrust_coefficient, hover.rotor_line, hover.measured_rotor_speed
    if k_t is None or k_t.refused:
        why = k_t.refused if k_t else hover.rotor_line_reason
        return f"# thrust_coefficient_n_per_radps2 kept: {why}"
    if measured is not None and not measured.refused:
        basis = (
            f"hover ω_h {measured.value:.0f} ± {measured.uncertainty:.0f} rad/s measured by "
            "the ESCs"
        )
    else:
        assert line is not None  # k_T is identified from a measured ω_h or the line
        basis = f"hover rotor line {line.frequency.value:.1f} ± {line.frequency.uncertainty:.1f} Hz"
    return f"thrust_coefficient_n_per_radps2 = {k_t.value:.4g}   # [identified] {source}, {basis}"
