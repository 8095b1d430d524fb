"""Power in hover, shared by the rotor line's check and the battery's efficiency: the
battery's V·I less the avionics, the rotors' shaft power at a speed; and a series' samples
inside windows."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

from px4_logs import FlightLog
from quad_model.frames import STANDARD_GRAVITY_MPS2
from quad_model.vehicle import Vehicle
from rig.identify.bounds import QUAD_ROTORS


def mean_in(time_s: NDArray, values: NDArray, windows: Iterable[tuple[float, float]]) -> NDArray:
    """The samples of ``values`` that fall inside any of ``windows`` (for their mean)."""
    mask = np.zeros(time_s.size, dtype=bool)
    for a, b in windows:
        mask |= (time_s >= a) & (time_s < b)
    return values[mask]


def hover_power_into_motors(
    log: FlightLog, windows: tuple[tuple[float, float], ...], avionics_w: float
) -> float | None:
    """The battery's mean V·I in the hover windows less the avionics; None when the log
    holds no voltage and current there."""
    battery = log.topics.get("battery_status", {})
    if not {"voltage_v", "current_a"} <= battery.keys():
        return None
    electric = mean_in(
        log.time_s("battery_status"), battery["voltage_v"] * battery["current_a"], windows
    )
    electric = electric[np.isfinite(electric)]
    return float(electric.mean()) - avionics_w if electric.size else None


def shaft_power_w(vehicle: Vehicle, density: float, speed_radps: float) -> float:
    """All rotors' shaft power at ``speed_radps``: 4·k_Q·ω³, k_Q at the air density."""
    prop = vehicle.propulsion
    k_q = prop.torque_coefficient_nm_per_radps2 * density / prop.reference_air_density_kgpm3
    return QUAD_ROTORS * k_q * speed_radps**3


def hover_thrust_coefficient(vehicle: Vehicle, speed_radps: float, density: float) -> float:
    """k_T at the vehicle's reference air density from the hover rotor speed measured at
    ``density``: the rotors together hold the weight, N·k_T·ω_h² = mg."""
    reference = vehicle.propulsion.reference_air_density_kgpm3
    weight = vehicle.body.mass_kg * STANDARD_GRAVITY_MPS2
    return weight / (QUAD_ROTORS * speed_radps**2) * reference / density
