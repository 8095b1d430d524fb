"""rig.identify.wind: the hover-tilt wind estimate against the drag balance it inverts, and on the
real X500 flight (its EKF2 estimated no wind: cs_wind 0, estimator_states wind 0)."""

import math
from pathlib import Path

import numpy as np
import pytest

from px4_logs import FlightLog, LogError
from quad_model.frames import STANDARD_GRAVITY_MPS2
from quad_model.vehicle import load_vehicle
from rig.identify.bounds import QUAD_ROTORS
from rig.identify.wind import _wind_from_tilt, estimate_wind

X500_LOG = (
    Path(__file__).resolve().parents[2] / "data/flight_logs/px4_x500v2_v6xrt_flight_2026-03-20.ulg"
)


@pytest.mark.parametrize("tilt_deg", [1.0, 4.0, 10.0])
def test_the_wind_balances_the_thrusts_horizontal_part(tilt_deg):
    """Leaning θ towards north-east: the wind blows from the north-east (towards −NE) at the
    speed whose drag, ½ρ·CdA·v² + 4·k_rd·ω_h·v, equals m·g·tan θ."""
    vehicle = load_vehicle("x500_v2")
    rho = vehicle.propulsion.reference_air_density_kgpm3
    tilt = math.radians(tilt_deg)
    lean = np.array([1.0, 1.0]) / math.sqrt(2.0)
    thrust_axis = np.array([*(math.sin(tilt) * lean), -math.cos(tilt)])
    wind = _wind_from_tilt(thrust_axis, np.array([0.0, 0.0, -1.0]), vehicle, rho)
    np.testing.assert_allclose(wind / np.linalg.norm(wind), -lean, atol=1e-12)
    speed = float(np.linalg.norm(wind))
    linear = (
        QUAD_ROTORS
        * vehicle.propulsion.rotor_drag_coefficient_ns_per_m_rad
        * vehicle.hover_rotor_speed_radps
    )
    drag = 0.5 * rho * np.mean(vehicle.body.drag_area_m2[:2]) * speed**2 + linear * speed
    weight = vehicle.body.mass_kg * STANDARD_GRAVITY_MPS2
    assert drag == pytest.approx(weight * math.tan(tilt), rel=1e-9)


def test_the_x500_flights_wind():
    """Four hover windows, the thrust axis against its attitude on the ground: about 5 m/s
    from the north-north-east, the windows and the level reference spread ±2 m/s (4.2 m/s
    with Gazebo's thrust coefficient, whose faster rotors carried more rotor drag)."""
    wind = estimate_wind(FlightLog.read(X500_LOG), load_vehicle("x500_v2"))
    assert len(wind.windows_s) == 4
    assert wind.speed_mps == pytest.approx(4.8, abs=0.3)
    assert wind.from_deg == pytest.approx(19.0, abs=10.0)
    assert 0.5 < wind.bound_mps < 3.0
    assert wind.steady_ned_mps[2] == 0.0
    assert "attitude on the ground" in wind.describe()


def test_an_unreadable_log_gives_one_line(tmp_path):
    path = tmp_path / "empty.ulg"
    path.write_bytes(b"not a ulog")
    with pytest.raises(LogError, match=r"empty\.ulg: not a readable ULog"):
        estimate_wind(FlightLog.read(path), load_vehicle("x500_v2"))
