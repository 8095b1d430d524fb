"""The wind of a real flight, estimated from its hover (``rig replay`` flies it).

PX4 estimates wind only with airspeed or drag fusion (EKF2_DRAG_CTRL); a multicopter log
without them has ``estimator_states`` wind at 0 and no ``wind`` topic, so the wind comes from
the thrust/attitude residual instead. In a steady hover the ground velocity is about 0 and the
vehicle leans into the wind: the horizontal part of the thrust (m·g·tan θ, θ the tilt of the
thrust axis) balances the drag of the air blowing past, which the vehicle model gives as body
drag ½ρ·CdA·v² plus the rotors' induced drag 4·k_rd·ω_h·v. Solving that for v per hover
window gives the wind there; the mean over the windows is flown, their spread is the bound.

The tilt is taken from the attitude on the ground before take-off: a board mounted a degree
off level, or a sloped take-off spot, reads as that much tilt in the air. Both readings (from
the ground's attitude and from the horizon) enter the bound, since the log cannot tell them
apart.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from px4_logs import FlightLog, LogError
from quad_model.frames import STANDARD_GRAVITY_MPS2, body_to_ned
from quad_model.vehicle import Vehicle
from rig.errors import RigError
from rig.identify.bounds import QUAD_ROTORS


class WindEstimateError(RigError):
    """The log cannot give a wind estimate; one line."""


@dataclass(frozen=True)
class WindEstimate:
    """The steady wind the replay flies (NED, m/s, blowing towards) and how far off it may be."""

    steady_ned_mps: tuple[float, float, float]
    #: The largest difference from the flown wind among the hover windows' estimates, with
    #: and without the ground's attitude as level (m/s).
    bound_mps: float
    windows_s: tuple[tuple[float, float], ...]
    method: str

    @property
    def speed_mps(self) -> float:
        return float(math.hypot(*self.steady_ned_mps[:2]))

    @property
    def from_deg(self) -> float:
        """Where it blows from, degrees clockwise from north (the meteorological direction)."""
        north, east = self.steady_ned_mps[:2]
        return float(math.degrees(math.atan2(-east, -north)) % 360.0)

    def describe(self) -> str:
        return (
            f"{self.speed_mps:.1f} ± {self.bound_mps:.1f} m/s from {self.from_deg:.0f}° "
            f"({self.method})"
        )

    def summary(self) -> dict:
        return {
            "steady_ned_mps": list(self.steady_ned_mps),
            "speed_mps": self.speed_mps,
            "from_deg": self.from_deg,
            "bound_mps": self.bound_mps,
            "windows_s": [list(w) for w in self.windows_s],
            "method": self.method,
        }


def estimate_wind(log: FlightLog, vehicle: Vehicle) -> WindEstimate:
    """The steady wind of the log's hover windows for ``vehicle``'s drag."""
    path, topics = log.path, log.topics
    if "vehicle_attitude" not in topics:
        raise WindEstimateError(f"{path}: no topic 'vehicle_attitude' (the wind estimate's tilt)")
    try:  # the log's one line (no airborne span, no velocity) is why there is no estimate
        windows, take_off = log.hover_windows(), log.airborne_span()[0]
    except LogError as error:
        raise WindEstimateError(str(error)) from None
    if not windows:
        raise WindEstimateError(f"{path}: no steady hover to estimate the wind from")
    attitude = topics["vehicle_attitude"]
    time_s = attitude["timestamp"] * 1e-6
    quats = np.column_stack([attitude[f"q[{i}]"] for i in range(4)]).astype(float)
    thrust_axes = np.array([body_to_ned(q, np.array([0.0, 0.0, -1.0])) for q in quats])
    on_ground = time_s < take_off
    levels = [np.array([0.0, 0.0, -1.0])]
    if on_ground.any():
        levels.append(_unit(thrust_axes[on_ground].mean(axis=0)))
    density = _density(topics, vehicle)
    estimates = []
    for level in levels:
        per_window = []
        for start, end in windows:
            inside = (time_s >= start) & (time_s < end)
            axis = _unit(thrust_axes[inside].mean(axis=0))
            per_window.append(_wind_from_tilt(axis, level, vehicle, density))
        estimates.append(per_window)
    flown = np.mean(estimates[-1], axis=0)  # from the ground's attitude when there is one
    everything = np.array([w for per_window in estimates for w in per_window])
    bound = float(np.max(np.linalg.norm(everything - flown, axis=1)))
    level_from = "the attitude on the ground" if len(levels) > 1 else "the horizon"
    method = (
        f"thrust tilt in {len(windows)} hover window(s) against {level_from}, "
        f"drag of {vehicle.name} at ρ {density:.3f} kg/m³"
    )
    steady = (float(flown[0]), float(flown[1]), 0.0)
    return WindEstimate(steady, bound, tuple(windows), method)


def _unit(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return v / np.linalg.norm(v)


def _density(topics: Mapping[str, Mapping[str, NDArray[Any]]], vehicle: Vehicle) -> float:
    air = topics.get("vehicle_air_data")
    if air is not None and "rho" in air:
        return float(np.mean(air["rho"]))
    return vehicle.propulsion.reference_air_density_kgpm3


def _wind_from_tilt(
    thrust_axis: NDArray[np.float64], level: NDArray[np.float64], vehicle: Vehicle, density: float
) -> NDArray[np.float64]:
    """The horizontal wind (N, E) that tilts a hovering vehicle's thrust from ``level`` to
    ``thrust_axis`` (unit vectors, NED, thrust direction)."""
    lean = thrust_axis[:2] - level[:2]  # horizontal thrust per unit thrust, level removed
    lean_size = float(np.linalg.norm(lean))
    if lean_size == 0.0:
        return np.zeros(2)
    weight = vehicle.body.mass_kg * STANDARD_GRAVITY_MPS2
    force = weight * lean_size / max(-thrust_axis[2], 1e-6)
    prop = vehicle.propulsion
    rho_ratio = density / prop.reference_air_density_kgpm3
    hover_speed = vehicle.hover_rotor_speed_radps / math.sqrt(rho_ratio)
    quadratic = 0.5 * density * float(np.mean(vehicle.body.drag_area_m2[:2]))
    linear = QUAD_ROTORS * prop.rotor_drag_coefficient_ns_per_m_rad * hover_speed
    # ½ρ·CdA·v² + linear·v = force, the positive root (written so that CdA = 0 is linear)
    speed = 2.0 * force / (linear + math.sqrt(linear * linear + 4.0 * quadratic * force))
    # the vehicle leans into the wind: the wind blows against the thrust's horizontal part
    return -speed * lean / lean_size
