"""The world around the vehicle: ISA atmosphere, Earth's magnetic field, wind.

The atmosphere functions are compiled with numba (callable from Python as usual) so the
5 kHz kernel and the sensor models share one definition.
"""

import math
from typing import Annotated

import numpy as np
from numba import njit
from numpy.typing import NDArray
from pydantic import Field

from hil_config import FieldError, NonNegative, Number, UnitInterval, Vector3, table
from quad_model.frames import GAUSS_PER_NANOTESLA, STANDARD_GRAVITY_MPS2

# ISA troposphere (ISO 2533:1975 / ICAO Doc 7488): sea-level values and lapse rate.
ISA_SEA_LEVEL_PRESSURE_PA = 101325.0
ISA_SEA_LEVEL_TEMPERATURE_K = 288.15
ISA_LAPSE_RATE_KPM = 0.0065
ISA_TROPOPAUSE_M = 11000.0
#: Specific gas constant of dry air, J/(kg·K) (ISA value).
DRY_AIR_GAS_CONSTANT = 287.05287
KELVIN_AT_0_DEGC = 273.15
_ISA_PRESSURE_EXPONENT = STANDARD_GRAVITY_MPS2 / (DRY_AIR_GAS_CONSTANT * ISA_LAPSE_RATE_KPM)


class EnvironmentConfigError(FieldError):
    """An environment setting is outside what the model covers; names the key."""


@njit(cache=True)
def isa_temperature_k(altitude_m: float) -> float:
    """ISA temperature at a geopotential altitude in the troposphere (K)."""
    return ISA_SEA_LEVEL_TEMPERATURE_K - ISA_LAPSE_RATE_KPM * altitude_m


@njit(cache=True)
def isa_pressure_pa(altitude_m: float) -> float:
    """ISA static pressure in the troposphere (Pa): p0·(T/T0)^(g0/(R·L))."""
    return (
        ISA_SEA_LEVEL_PRESSURE_PA
        * (isa_temperature_k(altitude_m) / ISA_SEA_LEVEL_TEMPERATURE_K) ** _ISA_PRESSURE_EXPONENT
    )


@njit(cache=True)
def isa_density_kgpm3(altitude_m: float) -> float:
    """ISA air density (kg/m³) from the ideal-gas law."""
    return isa_pressure_pa(altitude_m) / (DRY_AIR_GAS_CONSTANT * isa_temperature_k(altitude_m))


@table
class GeoPoint:
    """A WGS-84 position; altitude above mean sea level."""

    lat_deg: Annotated[Number, Field(ge=-90, le=90)]
    lon_deg: Annotated[Number, Field(ge=-180, le=180)]
    alt_amsl_m: Number


#: PX4 SITL's default home (``PX4_HOME_LAT/LON/ALT``, Zurich).
PX4_DEFAULT_HOME = GeoPoint(lat_deg=47.397742, lon_deg=8.545594, alt_amsl_m=488.0)


@table
class MagneticField:
    """Earth's field at the flying site, as a navigator states it.

    Declination is east-positive, inclination down-positive. Give the three numbers directly
    (from a chart, or a survey at the site) or look them up in NOAA's World Magnetic Model
    with :meth:`from_wmm`.
    """

    declination_deg: Number
    inclination_deg: Number
    intensity_gauss: Number

    def __post_init__(self) -> None:
        if not 0.0 < self.intensity_gauss < 1.0:
            raise EnvironmentConfigError(
                "intensity_gauss", self.intensity_gauss, "is not Earth-like (0..1 G)"
            )
        if not -90.0 <= self.inclination_deg <= 90.0:
            raise EnvironmentConfigError("inclination_deg", self.inclination_deg, "not in ±90°")

    def ned_gauss(self) -> NDArray[np.float64]:
        """Field vector in NED (gauss)."""
        dec, inc = math.radians(self.declination_deg), math.radians(self.inclination_deg)
        horizontal = self.intensity_gauss * math.cos(inc)
        return np.array(
            [
                horizontal * math.cos(dec),
                horizontal * math.sin(dec),
                self.intensity_gauss * math.sin(inc),
            ]
        )

    @classmethod
    def from_wmm(cls, point: GeoPoint, decimal_year: float) -> "MagneticField":
        """Look the field up in the World Magnetic Model (NOAA's ``wmm-calculator``).

        The date is explicit, never "today", so a run is reproducible. WMM2025 covers
        2024-11-13 to 2030-01-01.
        """
        from wmm import wmm_calc  # imported here: only this look-up needs it

        model = wmm_calc()
        model.setup_time(dyear=decimal_year)
        model.setup_env(point.lat_deg, point.lon_deg, point.alt_amsl_m, unit="m", msl=True)
        elements = model.get_all()
        return cls(
            declination_deg=float(elements["dec"][0]),
            inclination_deg=float(elements["inc"][0]),
            intensity_gauss=float(elements["f"][0]) * GAUSS_PER_NANOTESLA,
        )


#: WMM2025 at PX4's default home on 2026-01-01 (``MagneticField.from_wmm(PX4_DEFAULT_HOME,
#: 2026.0)``, pinned by a test): NED ≈ (0.215, 0.013, 0.433) G, which PX4's EKF2_MAG_CHECK
#: accepts there.
DEFAULT_MAGNETIC_FIELD = MagneticField(
    declination_deg=3.5468, inclination_deg=63.5203, intensity_gauss=0.483637
)


@table
class Wind:
    """Steady wind plus Dryden turbulence (MIL-F-8785C low-altitude model).

    ``wind_at_6m_mps`` is W20, the mean wind speed 20 ft above ground that sets the
    turbulence intensity (light ≈ 7.7 m/s, moderate ≈ 15.4 m/s in the standard); 0 turns
    turbulence off. The turbulence is a random process drawn from the model's seeded
    generator.
    """

    steady_ned_mps: Vector3 = (0.0, 0.0, 0.0)
    wind_at_6m_mps: Number = 0.0

    def __post_init__(self) -> None:
        if len(self.steady_ned_mps) != 3:
            raise EnvironmentConfigError("steady_ned_mps", self.steady_ned_mps, "is not 3 values")
        if self.wind_at_6m_mps < 0.0:
            raise EnvironmentConfigError("wind_at_6m_mps", self.wind_at_6m_mps, "is negative")


@table
class Surface:
    """What a downward camera sees of the ground: how textured it is and how lit.

    An optical-flow camera tracks features of the ground's image; a featureless floor, snow
    or still water gives it none, and in dim light its exposure runs out
    (:class:`~quad_model.vehicle.OpticalFlowParams`).
    """

    #: Visible texture, 0 (featureless) to 1 (gravel, a printed mat, grass).
    texture: UnitInterval = 0.8
    #: Light on the ground: about 50 lux in a dim room, 500 in an office, 10,000 and more
    #: outdoors by day.
    illuminance_lux: NonNegative = 10_000.0


@table
class Environment:
    """Flying site: home (the NED origin, on the ground), magnetic field, wind, weather.

    The ground is the plane through home (NED z = 0), its look the ``surface``.
    ``temperature_offset_k`` shifts the ISA temperature (a hot or cold day) for the sensors.
    """

    home: GeoPoint = PX4_DEFAULT_HOME
    magnetic_field: MagneticField = DEFAULT_MAGNETIC_FIELD
    wind: Wind = Wind()
    surface: Surface = Surface()
    temperature_offset_k: Number = 0.0

    def __post_init__(self) -> None:
        if not -500.0 <= self.home.alt_amsl_m <= ISA_TROPOPAUSE_M - 1000.0:
            raise EnvironmentConfigError(
                "home.alt_amsl_m",
                self.home.alt_amsl_m,
                "is outside the ISA troposphere model (-500..10000 m)",
            )

    def altitude_amsl_m(self, position_ned_m: NDArray[np.float64]) -> float:
        """Altitude above mean sea level of a local NED point."""
        return self.home.alt_amsl_m - float(position_ned_m[2])

    def air_temperature_degc(self, altitude_amsl_m: float) -> float:
        """Outside air temperature (°C)."""
        return isa_temperature_k(altitude_amsl_m) + self.temperature_offset_k - KELVIN_AT_0_DEGC

    def static_pressure_pa(self, altitude_amsl_m: float) -> float:
        """Static pressure (Pa); ISA pressure is kept on a hot or cold day (QNH 1013.25)."""
        return isa_pressure_pa(altitude_amsl_m)
