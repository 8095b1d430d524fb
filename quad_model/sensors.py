"""Sensor physics: ground truth → SI samples, before any chip.

The emulated chips (``fpga_hdl``) quantize and saturate like the real parts, so nothing here
quantizes or clips. Each model draws from its own generator, spawned from the one the caller
injects, so adding a sensor or changing a rate never changes another sensor's numbers.

White noise follows the discrete-time convention of Gazebo/PX4 SITL and Kalibr: a sensor
with noise density N sampled at rate f has per-sample σ = N·√f (N/√Δt).
"""

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from quad_model.environment import Environment
from quad_model.frames import ned_to_body, ned_to_geodetic
from quad_model.model import VehicleTruth
from quad_model.vehicle import ROTOR_COUNT, Vehicle

DEFAULT_IMU_RATE_HZ = 1000.0
DEFAULT_MAG_RATE_HZ = 100.0
DEFAULT_BARO_RATE_HZ = 50.0
#: GNSS fix types as MAVLink's GPS_FIX_TYPE: 0 no GPS, 1 no fix, 3 3D fix.
GPS_FIX_3D = 3


class SensorConfigError(ValueError):
    """A sensor setting is unusable; the message names it."""


@dataclass(frozen=True)
class ImuSample:
    time_s: float
    #: Specific force, FRD (level at rest ≈ (0, 0, -9.81)).
    accel_mps2: NDArray[np.float64]
    gyro_radps: NDArray[np.float64]
    temperature_degc: float


@dataclass(frozen=True)
class BaroSample:
    time_s: float
    pressure_pa: float
    temperature_degc: float


@dataclass(frozen=True)
class MagSample:
    time_s: float
    field_gauss: NDArray[np.float64]  # FRD


@dataclass(frozen=True)
class GpsSample:
    #: When the receiver outputs the fix (its measurement epoch + latency).
    time_s: float
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    vel_ned_mps: NDArray[np.float64]
    eph_m: float
    epv_m: float
    fix_type: int
    satellites_visible: int


def _check_rate(rate_hz: float, name: str) -> float:
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise SensorConfigError(f"{name}={rate_hz} must be a positive rate")
    return float(rate_hz)


def _small_rotation(angles_rad: NDArray[np.float64]) -> NDArray[np.float64]:
    """First-order rotation I + [θ]×: the misalignment of a sensor triad."""
    x, y, z = angles_rad
    return np.array([[1.0, -z, y], [z, 1.0, -x], [-y, x, 1.0]])


class ImuModel:
    """Accelerometer + gyroscope: white noise, bias random walk, turn-on bias, scale factor,
    misalignment, temperature, and vibration driven by rotor speed.

    Vibration: each rotor adds tones at multiples of its shaft rate (1× imbalance, blade
    passing, ...) with amplitude ∝ (ω/ω_ref)², phase-locked to the rotor angle, plus
    broadband frame noise with the same speed scaling; nothing vibrates when rotors stop,
    which reproduces the paper's motors-off/motors-on sensor test.
    """

    def __init__(
        self,
        vehicle: Vehicle,
        environment: Environment,
        rng: np.random.Generator,
        rate_hz: float = DEFAULT_IMU_RATE_HZ,
    ) -> None:
        self.rate_hz = _check_rate(rate_hz, "imu rate_hz")
        self._imu = vehicle.imu
        self._vib = vehicle.vibration
        self._environment = environment
        self._rng = rng
        imu = self._imu
        self.gyro_noise_std_radps = imu.gyro_noise_density_radps_per_sqrthz * math.sqrt(rate_hz)
        self.accel_noise_std_mps2 = imu.accel_noise_density_mps2_per_sqrthz * math.sqrt(rate_hz)
        # Fixed errors of this unit, drawn once.
        self._gyro_bias = rng.normal(0.0, imu.gyro_turn_on_bias_std_radps, 3)
        self._accel_bias = rng.normal(0.0, imu.accel_turn_on_bias_std_mps2, 3)
        self._gyro_matrix = _small_rotation(rng.normal(0.0, imu.misalignment_std_rad, 3)) * (
            1.0 + rng.normal(0.0, imu.gyro_scale_error_std, 3)
        )
        self._accel_matrix = _small_rotation(rng.normal(0.0, imu.misalignment_std_rad, 3)) * (
            1.0 + rng.normal(0.0, imu.accel_scale_error_std, 3)
        )
        # Vibration: harmonic numbers and one random phase per (harmonic, rotor, axis).
        vib = self._vib
        self._accel_harmonics = np.arange(1, len(vib.accel_harmonic_amplitude_mps2) + 1)
        self._gyro_harmonics = np.arange(1, len(vib.gyro_harmonic_amplitude_radps) + 1)
        self._accel_phase = rng.uniform(0, 2 * np.pi, (len(self._accel_harmonics), ROTOR_COUNT, 3))
        self._gyro_phase = rng.uniform(0, 2 * np.pi, (len(self._gyro_harmonics), ROTOR_COUNT, 3))
        self._last_time_s: float | None = None

    def _vibration(
        self,
        speed_ratio_sq: NDArray[np.float64],
        rotor_angle_rad: NDArray[np.float64],
        harmonics: NDArray[np.int_],
        amplitudes: tuple[float, ...],
        phases: NDArray[np.float64],
        broadband_std: float,
        axis_gain: tuple[float, ...],
    ) -> NDArray[np.float64]:
        angle = harmonics[:, None, None] * rotor_angle_rad[None, :, None] + phases
        weight = np.asarray(amplitudes)[:, None] * speed_ratio_sq[None, :]
        tones = np.einsum("hr,hra->a", weight, np.sin(angle))
        broadband = broadband_std * math.sqrt(float(np.mean(speed_ratio_sq**2)))
        return (tones + broadband * self._rng.standard_normal(3)) * np.asarray(axis_gain)

    def sample(self, truth: VehicleTruth) -> ImuSample:
        """One IMU reading of ``truth`` (call at ``rate_hz`` for the stated noise)."""
        imu, vib = self._imu, self._vib
        dt = 1.0 / self.rate_hz if self._last_time_s is None else truth.time_s - self._last_time_s
        self._last_time_s = truth.time_s
        if dt > 0:
            sqrt_dt = math.sqrt(dt)
            self._gyro_bias += (
                imu.gyro_bias_random_walk_radps2_per_sqrthz
                * sqrt_dt
                * (self._rng.standard_normal(3))
            )
            self._accel_bias += (
                imu.accel_bias_random_walk_mps3_per_sqrthz
                * sqrt_dt
                * (self._rng.standard_normal(3))
            )
        altitude = self._environment.altitude_amsl_m(truth.position_ned_m)
        temperature = self._environment.air_temperature_degc(altitude) + imu.self_heating_k
        delta_t = temperature - imu.reference_temperature_degc
        ratio_sq = (truth.rotor_speed_radps / vib.reference_rotor_speed_radps) ** 2
        angles = truth.rotor_angle_rad
        accel_vibration = self._vibration(
            ratio_sq,
            angles,
            self._accel_harmonics,
            vib.accel_harmonic_amplitude_mps2,
            self._accel_phase,
            vib.accel_broadband_std_mps2,
            vib.accel_axis_gain,
        )
        gyro_vibration = self._vibration(
            ratio_sq,
            angles,
            self._gyro_harmonics,
            vib.gyro_harmonic_amplitude_radps,
            self._gyro_phase,
            vib.gyro_broadband_std_radps,
            vib.gyro_axis_gain,
        )
        accel = (
            self._accel_matrix @ (truth.specific_force_frd_mps2 + accel_vibration)
            + self._accel_bias
            + imu.accel_bias_tempco_mps2_per_k * delta_t
            + self.accel_noise_std_mps2 * self._rng.standard_normal(3)
        )
        gyro = (
            self._gyro_matrix @ (truth.angular_rate_frd_radps + gyro_vibration)
            + self._gyro_bias
            + imu.gyro_bias_tempco_radps_per_k * delta_t
            + self.gyro_noise_std_radps * self._rng.standard_normal(3)
        )
        return ImuSample(truth.time_s, accel, gyro, temperature)


class BaroModel:
    """Static pressure (ISA at the vehicle's altitude) with white noise and a drifting offset."""

    def __init__(
        self, vehicle: Vehicle, environment: Environment, rng: np.random.Generator
    ) -> None:
        self._baro = vehicle.baro
        self._environment = environment
        self._rng = rng
        self._drift_pa = 0.0
        self._last_time_s: float | None = None

    def sample(self, truth: VehicleTruth) -> BaroSample:
        baro = self._baro
        if self._last_time_s is not None and truth.time_s > self._last_time_s:
            dt = truth.time_s - self._last_time_s
            self._drift_pa += (
                baro.drift_random_walk_pa_per_sqrts * math.sqrt(dt) * (self._rng.standard_normal())
            )
        self._last_time_s = truth.time_s
        altitude = self._environment.altitude_amsl_m(truth.position_ned_m)
        pressure = (
            self._environment.static_pressure_pa(altitude)
            + self._drift_pa
            + baro.noise_std_pa * self._rng.standard_normal()
        )
        temperature = self._environment.air_temperature_degc(altitude) + baro.self_heating_k
        return BaroSample(truth.time_s, float(pressure), temperature)


class MagModel:
    """Earth's field rotated into the body, plus the vehicle's hard-iron offset and noise."""

    def __init__(
        self, vehicle: Vehicle, environment: Environment, rng: np.random.Generator
    ) -> None:
        self._mag = vehicle.mag
        self._field_ned = environment.magnetic_field.ned_gauss()
        self._hard_iron = np.asarray(vehicle.mag.hard_iron_frd_gauss)
        self._rng = rng

    def sample(self, truth: VehicleTruth) -> MagSample:
        field = ned_to_body(truth.attitude_quat, self._field_ned) + self._hard_iron
        field = field + self._mag.noise_std_gauss * self._rng.standard_normal(3)
        return MagSample(truth.time_s, field)


class GpsModel:
    """GNSS receiver: Gauss-Markov position error, velocity noise, latency, fix rate.

    Call :meth:`sample` every rig frame: it keeps the recent truth and returns a fix when
    one is due (epochs every 1/fix_rate s, each output ``latency_s`` after its epoch),
    otherwise None. Latency resolves to the calling period.
    """

    def __init__(
        self, vehicle: Vehicle, environment: Environment, rng: np.random.Generator
    ) -> None:
        self._gps = vehicle.gps
        self._home = environment.home
        self._rng = rng
        gps = self._gps
        self._period_s = 1.0 / gps.fix_rate_hz
        self._error_std = np.array(
            [gps.horizontal_error_std_m, gps.horizontal_error_std_m, gps.vertical_error_std_m]
        )
        self._error_m = self._error_std * rng.standard_normal(3)
        self._next_epoch_s = 0.0
        self._history: deque[tuple[float, NDArray[np.float64], NDArray[np.float64]]] = deque()

    def sample(self, truth: VehicleTruth) -> GpsSample | None:
        gps = self._gps
        now = truth.time_s
        self._history.append((now, truth.position_ned_m.copy(), truth.velocity_ned_mps.copy()))
        if now + 1e-9 < self._next_epoch_s + gps.latency_s:
            return None
        epoch = self._next_epoch_s
        # Skip epochs that were missed entirely (caller slower than the fix rate).
        while epoch + self._period_s + gps.latency_s <= now + 1e-9:
            epoch += self._period_s
        self._next_epoch_s = epoch + self._period_s
        while len(self._history) > 1 and self._history[1][0] <= epoch + 1e-9:
            self._history.popleft()
        _, position, velocity = self._history[0]
        decay = math.exp(-self._period_s / gps.error_correlation_time_s)
        self._error_m = self._error_m * decay + self._error_std * math.sqrt(
            1.0 - decay * decay
        ) * self._rng.standard_normal(3)
        lat, lon, alt = ned_to_geodetic(
            position + self._error_m, self._home.lat_deg, self._home.lon_deg, self._home.alt_amsl_m
        )
        velocity = velocity + gps.velocity_noise_std_mps * self._rng.standard_normal(3)
        return GpsSample(
            time_s=now,
            lat_deg=lat,
            lon_deg=lon,
            alt_amsl_m=alt,
            vel_ned_mps=velocity,
            eph_m=gps.horizontal_error_std_m,
            epv_m=gps.vertical_error_std_m,
            fix_type=GPS_FIX_3D,
            satellites_visible=gps.satellites_visible,
        )


@dataclass(frozen=True)
class SensorReadings:
    """What the sensors produced at one rig frame; None where a sensor was not due."""

    imu: ImuSample | None
    mag: MagSample | None
    baro: BaroSample | None
    gps: GpsSample | None


class SensorSuite:
    """All four sensors of a vehicle on their own schedules (the rig calls it each frame).

    A sensor is due when the frame time reaches its next slot on a fixed grid k/rate, so
    rates that do not divide the frame rate keep their long-run average.
    """

    def __init__(
        self,
        vehicle: Vehicle,
        environment: Environment,
        rng: np.random.Generator,
        imu_rate_hz: float = DEFAULT_IMU_RATE_HZ,
        mag_rate_hz: float = DEFAULT_MAG_RATE_HZ,
        baro_rate_hz: float = DEFAULT_BARO_RATE_HZ,
    ) -> None:
        imu_rng, mag_rng, baro_rng, gps_rng = rng.spawn(4)
        self.imu = ImuModel(vehicle, environment, imu_rng, imu_rate_hz)
        self.mag = MagModel(vehicle, environment, mag_rng)
        self.baro = BaroModel(vehicle, environment, baro_rng)
        self.gps = GpsModel(vehicle, environment, gps_rng)
        self._periods_s = {
            "imu": 1.0 / self.imu.rate_hz,
            "mag": 1.0 / _check_rate(mag_rate_hz, "mag_rate_hz"),
            "baro": 1.0 / _check_rate(baro_rate_hz, "baro_rate_hz"),
        }
        self._next_slot = dict.fromkeys(self._periods_s, 0)

    def _due(self, name: str, time_s: float) -> bool:
        slot = self._next_slot[name]
        period = self._periods_s[name]
        if time_s + 1e-9 < slot * period:
            return False
        self._next_slot[name] = math.floor(time_s / period + 1e-6) + 1
        return True

    def sample(self, truth: VehicleTruth) -> SensorReadings:
        t = truth.time_s
        return SensorReadings(
            imu=self.imu.sample(truth) if self._due("imu", t) else None,
            mag=self.mag.sample(truth) if self._due("mag", t) else None,
            baro=self.baro.sample(truth) if self._due("baro", t) else None,
            gps=self.gps.sample(truth),
        )


__all__ = [
    "BaroModel",
    "BaroSample",
    "GpsModel",
    "GpsSample",
    "ImuModel",
    "ImuSample",
    "MagModel",
    "MagSample",
    "SensorConfigError",
    "SensorReadings",
    "SensorSuite",
]
