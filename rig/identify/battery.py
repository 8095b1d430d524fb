"""The battery from the armed flight: internal resistance, the avionics' power and the
propulsion's efficiency."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from px4_logs import FlightLog
from quad_model.vehicle import Vehicle
from rig.identify.bounds import bounded, refusal
from rig.identify.power import mean_in, shaft_power_w
from rig.identify.results import BatteryIdentification, Estimate, HoverIdentification

#: Battery: the after-disarm current is the avionics' once the rotors have coasted down.
DISARM_SETTLE_S = 0.5


def identify_battery(
    log: FlightLog, hover: HoverIdentification, vehicle: Vehicle
) -> tuple[BatteryIdentification | None, str]:
    """Internal resistance, avionics power and propulsion efficiency (:mod:`rig.identify`)."""
    data = log.topics.get("battery_status")
    if data is None:
        return None, "no battery_status in the log"
    missing = [f for f in ("voltage_v", "current_a", "discharged_mah") if f not in data]
    if missing:
        return None, f"battery_status has no {', '.join(missing)}"
    time_s = log.time_s("battery_status")
    volts, amps, used_mah = (np.asarray(data[f], dtype=float)
                             for f in ("voltage_v", "current_a", "discharged_mah"))  # fmt: skip
    armed_from, armed_to, disarm_logged = log.armed_span()
    use = (time_s >= armed_from) & (time_s < armed_to) & np.isfinite(volts) & (amps > 0)
    if use.sum() < 20:
        return None, f"only {int(use.sum())} battery_status samples while armed with a current"
    design = np.column_stack([np.ones(use.sum()), -used_mah[use], -amps[use]])
    solution, *_ = np.linalg.lstsq(design, volts[use], rcond=None)
    residual = volts[use] - design @ solution
    covariance = np.var(residual, ddof=3) * np.linalg.pinv(design.T @ design)
    span = (float(time_s[use][0]), float(time_s[use][-1]))
    resistance = bounded(
        "internal resistance",
        Estimate(
            float(solution[2]),
            float(np.sqrt(covariance[2, 2])),
            f"V = E₀ − s·Q − R·I, least squares over {int(use.sum())} armed samples "
            f"(RMS residual {np.sqrt(np.mean(residual**2)) * 1e3:.0f} mV)",
            span,
        ),
    )
    # after a logged disarm only: the end of the airborne span may still idle the rotors
    after = (time_s >= armed_to + DISARM_SETTLE_S) & np.isfinite(volts) & (amps >= 0)
    avionics = None
    if disarm_logged and after.any():
        power = volts[after] * amps[after]
        avionics = bounded(
            "avionics power",
            Estimate(
                float(power.mean()),
                float(power.std()),
                f"V·I after the disarm (rotors stopped from {DISARM_SETTLE_S:g} s), "
                f"{int(after.sum())} samples ± σ",
                (float(time_s[after][0]), float(time_s[after][-1])),
            ),
        )
    efficiency, efficiency_reason = _propulsion_efficiency(
        mean_in(time_s, volts * amps, hover.windows_s),
        avionics.value if avionics and not avionics.refused else vehicle.battery.avionics_power_w,
        hover,
        vehicle,
    )
    return BatteryIdentification(resistance, avionics, efficiency, efficiency_reason), ""


def _propulsion_efficiency(
    electric_w: NDArray, avionics_w: float, hover: HoverIdentification, vehicle: Vehicle
) -> tuple[Estimate | None, str]:
    """The rotors' shaft power in hover over the battery's power into the motors (its
    samples ``electric_w`` in the hover windows, less the avionics)."""
    if electric_w.size == 0:
        return None, "no battery_status sample in the hover windows"
    into_motors = float(electric_w.mean()) - avionics_w
    shaft = shaft_power_w(vehicle, hover.air_density_kgpm3, hover.rotor_speed_radps)
    efficiency = shaft / into_motors if into_motors > 0 else math.inf
    # shaft power ∝ ω_h³: three times ω_h's relative uncertainty (measured or the line's)
    measured = hover.measured_rotor_speed
    if measured is not None and not measured.refused:
        speed_relative = measured.relative_uncertainty
    else:
        line = hover.rotor_line
        speed_relative = line.frequency.relative_uncertainty if line else 0.0
    relative = math.hypot(
        3.0 * speed_relative,
        float(electric_w.std() / electric_w.mean()) / math.sqrt(electric_w.size),
    )
    reason = refusal("propulsion efficiency", efficiency, efficiency * relative)
    if reason:
        return None, (
            f"the rotors' shaft power in hover ({shaft:.0f} W at {hover.rotor_speed_radps:.0f} "
            f"rad/s) against {into_motors:.0f} W into the motors: {reason}; the torque "
            "coefficient or the rotor speed is off"
        )
    return Estimate(
        efficiency,
        efficiency * relative,
        f"shaft 4·k_Q·ω_h³ = {shaft:.0f} W over {into_motors:.0f} W into the motors in hover "
        "(battery V·I less the avionics)",
        (hover.windows_s[0][0], hover.windows_s[-1][1]),
    ), ""
