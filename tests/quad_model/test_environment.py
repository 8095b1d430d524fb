"""ISA atmosphere against the standard's table, magnetic field geometry and the WMM lookup."""

import math

import numpy as np
import pytest

from quad_model.environment import (
    DEFAULT_MAGNETIC_FIELD,
    PX4_DEFAULT_HOME,
    Environment,
    EnvironmentConfigError,
    GeoPoint,
    MagneticField,
    Wind,
    isa_density_kgpm3,
    isa_pressure_pa,
    isa_temperature_k,
)


# ICAO standard atmosphere table (geopotential altitude): T (K), p (Pa), ρ (kg/m³).
@pytest.mark.parametrize(
    ("altitude_m", "temperature_k", "pressure_pa", "density_kgpm3"),
    [
        (0.0, 288.15, 101325.0, 1.2250),
        (1000.0, 281.65, 89874.6, 1.1116),
        (5000.0, 255.65, 54019.9, 0.73612),
        (11000.0, 216.65, 22632.1, 0.36392),
    ],
)
def test_isa_matches_standard_table(altitude_m, temperature_k, pressure_pa, density_kgpm3):
    assert isa_temperature_k(altitude_m) == pytest.approx(temperature_k, abs=1e-9)
    assert isa_pressure_pa(altitude_m) == pytest.approx(pressure_pa, rel=2e-5)
    assert isa_density_kgpm3(altitude_m) == pytest.approx(density_kgpm3, rel=1e-4)


def test_field_vector_from_declination_inclination_intensity():
    field = MagneticField(declination_deg=90.0, inclination_deg=30.0, intensity_gauss=0.5)
    # Declination 90° points the horizontal part east; inclination tips it down.
    np.testing.assert_allclose(
        field.ned_gauss(), [0.0, 0.5 * math.cos(math.radians(30)), 0.25], atol=1e-12
    )


def test_default_field_is_wmm_at_px4_home_and_passes_px4_check():
    looked_up = MagneticField.from_wmm(PX4_DEFAULT_HOME, 2026.0)
    assert looked_up.declination_deg == pytest.approx(
        DEFAULT_MAGNETIC_FIELD.declination_deg, abs=1e-3
    )
    assert looked_up.inclination_deg == pytest.approx(
        DEFAULT_MAGNETIC_FIELD.inclination_deg, abs=1e-3
    )
    assert looked_up.intensity_gauss == pytest.approx(
        DEFAULT_MAGNETIC_FIELD.intensity_gauss, rel=1e-5
    )
    # PX4_SIM_CONTRACT.md: about (0.214, 0.011, 0.430) G in NED passes EKF2_MAG_CHECK there.
    np.testing.assert_allclose(
        DEFAULT_MAGNETIC_FIELD.ned_gauss(), [0.214, 0.011, 0.430], atol=0.005
    )


def test_environment_settings_are_checked():
    with pytest.raises(EnvironmentConfigError, match=r"^intensity_gauss = 2.0: is not Earth-like"):
        MagneticField(declination_deg=0.0, inclination_deg=60.0, intensity_gauss=2.0)
    with pytest.raises(EnvironmentConfigError, match=r"^wind_at_6m_mps = -1.0: is negative"):
        Wind(wind_at_6m_mps=-1.0)
    with pytest.raises(EnvironmentConfigError, match=r"^home.alt_amsl_m = 20000.0: is outside"):
        Environment(home=GeoPoint(0.0, 0.0, 20000.0))


def test_air_temperature_and_pressure_at_vehicle():
    env = Environment(temperature_offset_k=10.0)
    altitude = env.altitude_amsl_m(np.array([0.0, 0.0, -12.0]))
    assert altitude == pytest.approx(500.0)
    assert env.air_temperature_degc(altitude) == pytest.approx(288.15 - 3.25 - 273.15 + 10.0)
    assert env.static_pressure_pa(altitude) == pytest.approx(isa_pressure_pa(500.0))
