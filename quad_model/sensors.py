"""Sensor physics: ground truth → SI samples, before any chip.

The emulated chips (``fpga_hdl``) quantize and saturate like the real parts, so nothing here
quantizes or clips. Each model draws from its own generator, spawned from the one the caller
injects, so adding a sensor or changing a rate never changes another sensor's numbers.

White noise follows the discrete-time convention of Gazebo/PX4 SITL and Kalibr: a sensor
with noise density N sampled at rate f has per-sample σ = N·√f (N/√Δt).

Speed: the rig samples every 1 ms frame, so each model draws its normal variates in blocks
(:class:`NormalBlocks`) and the IMU's arithmetic is one compiled call
(:mod:`quad_model._sensor_kernels`). The draws keep their order, so a seed gives the same
numbers as the plain numpy formulation (a test compares the two).
"""

import math
from collections import deque
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from numpy.typing import NDArray

from quad_model import _sensor_kernels as _kernels
from quad_model.environment import Environment, Surface
from quad_model.frames import body_to_ned, ned_to_body, ned_to_geodetic
from quad_model.model import VehicleTruth
from quad_model.vehicle import LEVEL_TABLES, OpticalFlowParams, RangefinderParams, Vehicle

DEFAULT_IMU_RATE_HZ = 1000.0
DEFAULT_MAG_RATE_HZ = 100.0
DEFAULT_BARO_RATE_HZ = 50.0
#: GNSS fix types as MAVLink's GPS_FIX_TYPE: 0 no GPS, 1 no fix, 3 3D fix.
GPS_FIX_3D = 3


class SensorConfigError(ValueError):
    """A sensor setting is unusable; the message names it."""


@dataclass(frozen=True)
class ImuSample:
    time_us: int
    #: Specific force, FRD (level at rest ≈ (0, 0, -9.81)).
    accel_mps2: NDArray[np.float64]
    gyro_radps: NDArray[np.float64]
    temperature_degc: float


@dataclass(frozen=True)
class BaroSample:
    time_us: int
    pressure_pa: float
    temperature_degc: float


@dataclass(frozen=True)
class MagSample:
    time_us: int
    field_gauss: NDArray[np.float64]  # FRD


@dataclass(frozen=True)
class GpsSample:
    #: When the receiver outputs the fix (its measurement epoch + latency).
    time_us: int
    #: The measurement epoch the fix is of: the receiver's time of week (NAV-PVT iTOW).
    epoch_us: int
    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    vel_ned_mps: NDArray[np.float64]
    eph_m: float
    epv_m: float
    fix_type: int
    satellites_visible: int


@dataclass(frozen=True)
class RangeSample:
    time_us: int
    #: Measured distance along the beam; None when nothing returns (out of range, tilted).
    distance_m: float | None


@dataclass(frozen=True)
class FlowSample:
    """One optical-flow camera frame: how far the ground's image moved, how well it was seen."""

    time_us: int
    #: The image's motion over the frame about body x and y (rad), in PX4's sign convention:
    #: a right-handed rotation of the vehicle about an axis reads positive, a motion along
    #: +y reads negative about x, along +x positive about y.
    flow_xy_rad: tuple[float, float]
    #: Ground features tracked, 0..255; with none (0) the motion reads zero.
    squal: int
    #: How long the frame was exposed (s).
    exposure_s: float


def _check_rate(rate_hz: float, name: str) -> float:
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise SensorConfigError(f"{name}={rate_hz} must be a positive rate")
    return float(rate_hz)


def _small_rotation(angles_rad: NDArray[np.float64]) -> NDArray[np.float64]:
    """First-order rotation I + [θ]×: the misalignment of a sensor triad."""
    x, y, z = angles_rad
    return np.array([[1.0, -z, y], [z, 1.0, -x], [-y, x, 1.0]])


class NormalBlocks:
    """Standard normal variates read ahead from one generator and handed out in order.

    One ``standard_normal(block_size)`` call replaces a call per sample (each costs ~0.6 µs
    of numpy overhead for three numbers). A Generator fills an array draw by draw from its
    stream, so the values equal those of consecutive small calls: the same seed gives the
    same numbers. The owner must be the generator's only user from then on, since the
    generator runs ahead of the values handed out.
    """

    def __init__(self, rng: np.random.Generator, block_size: int = 2048) -> None:
        self._rng = rng
        self._values = self._readonly(rng.standard_normal(block_size))
        self._next = 0

    @staticmethod
    def _readonly(values: NDArray[np.float64]) -> NDArray[np.float64]:
        values.flags.writeable = False  # callers get views: none may change the stream
        return values

    def take(self, count: int) -> NDArray[np.float64]:
        """The next ``count`` variates of the stream."""
        start = self._next
        values = self._values
        if start + count > values.size:
            unread = values[start:]
            fresh = self._rng.standard_normal(max(values.size, count) - unread.size)
            values = self._values = self._readonly(np.concatenate((unread, fresh)))
            start = 0
        self._next = start + count
        return values[start : start + count]


class ImuModel:
    """Accelerometer + gyroscope: white noise, bias random walk, turn-on bias, scale factor,
    misalignment, temperature, and vibration driven by rotor speed.

    Vibration: each rotor adds tones at multiples of its shaft rate (1× imbalance, blade
    passing, ...) with amplitude ∝ (ω/ω_ref)² (or the level measured at the vehicle's
    operating points, :class:`~quad_model.vehicle.VibrationParams`), phase-locked to the
    rotor angle, plus broadband frame noise scaled alike; nothing vibrates when rotors stop,
    which reproduces the paper's motors-off/motors-on sensor test.

    The model owns ``rng``. It draws, in this order, the unit's fixed errors (gyro then accel
    turn-on bias; gyro misalignment and scale; accel misalignment and scale; accel then gyro
    tone phases), then per sample: gyro and accel bias walk (when time advanced), accel and
    gyro broadband vibration, accel and gyro white noise.
    """

    def __init__(
        self,
        vehicle: Vehicle,
        environment: Environment,
        rng: np.random.Generator,
        rate_hz: float = DEFAULT_IMU_RATE_HZ,
    ) -> None:
        self.rate_hz = _check_rate(rate_hz, "imu rate_hz")
        imu = self._imu = vehicle.imu
        vib = vehicle.vibration
        self._reference_rotor_speed_radps = vib.reference_rotor_speed_radps
        # The operating points as the kernel's table levels[triad, tone|broadband, axis, point].
        self._level_speed_radps = np.array(vib.level_rotor_speed_radps, dtype=float)
        levels = np.array([getattr(vib, name) for name in LEVEL_TABLES], dtype=float)
        points = self._level_speed_radps.size
        self._levels = np.ascontiguousarray(
            levels.reshape(_kernels.TRIADS, 2, points, 3).transpose(0, 1, 3, 2)
        )
        self._environment = environment
        #: White noise σ per sample of each sensor axis (x, y, z).
        self.gyro_noise_std_radps = (
            imu.gyro_noise_density_radps_per_sqrthz * math.sqrt(rate_hz)
        ) * np.asarray(imu.gyro_noise_axis_gain)
        self.accel_noise_std_mps2 = (
            imu.accel_noise_density_mps2_per_sqrthz * math.sqrt(rate_hz)
        ) * np.asarray(imu.accel_noise_axis_gain)
        # Fixed errors of this unit, drawn once.
        gyro_bias = rng.normal(0.0, imu.gyro_turn_on_bias_std_radps, 3)
        accel_bias = rng.normal(0.0, imu.accel_turn_on_bias_std_mps2, 3)
        gyro_matrix = _small_rotation(rng.normal(0.0, imu.misalignment_std_rad, 3)) * (
            1.0 + rng.normal(0.0, imu.gyro_scale_error_std, 3)
        )
        accel_matrix = _small_rotation(rng.normal(0.0, imu.misalignment_std_rad, 3)) * (
            1.0 + rng.normal(0.0, imu.accel_scale_error_std, 3)
        )
        amplitudes = (vib.accel_harmonic_amplitude_mps2, vib.gyro_harmonic_amplitude_radps)
        # One random phase per (harmonic, rotor, axis); accel's drawn first.
        rotors = vehicle.propulsion.rotor_count
        phases = [rng.uniform(0, 2 * np.pi, (len(a), rotors, 3)) for a in amplitudes]
        self._normals = NormalBlocks(rng)
        # The kernel's flat layout: one row per triad, in the order (ACCEL, GYRO).
        k = _kernels
        triad = self._triad = np.zeros((k.TRIADS, k.T_SIZE))
        triad[:, k.T_NOISE_STD : k.T_NOISE_STD + 3] = (
            self.accel_noise_std_mps2,
            self.gyro_noise_std_radps,
        )
        triad[:, k.T_BIAS_WALK] = (
            imu.accel_bias_random_walk_mps3_per_sqrthz,
            imu.gyro_bias_random_walk_radps2_per_sqrthz,
        )
        triad[:, k.T_TEMPCO] = imu.accel_bias_tempco_mps2_per_k, imu.gyro_bias_tempco_radps_per_k
        triad[:, k.T_BROADBAND_STD] = vib.accel_broadband_std_mps2, vib.gyro_broadband_std_radps
        triad[:, k.T_AXIS_GAIN : k.T_AXIS_GAIN + 3] = vib.accel_axis_gain, vib.gyro_axis_gain
        triad[:, k.T_MATRIX : k.T_MATRIX + 9] = accel_matrix.ravel(), gyro_matrix.ravel()
        self._bias = np.array([accel_bias, gyro_bias])  # the bias walks: kernel state
        # Each tone as its (A·cos φ, A·sin φ) pair; a triad with fewer harmonics is padded
        # with silent ones.
        harmonics = max(map(len, amplitudes))
        self._tone_quadrature = np.zeros((k.TRIADS, harmonics, rotors, 3, 2))
        for quadrature, amplitude, phase in zip(
            self._tone_quadrature, amplitudes, phases, strict=True
        ):
            weight = np.asarray(amplitude)[:, None, None]
            quadrature[: len(amplitude), ..., 0] = weight * np.cos(phase)
            quadrature[: len(amplitude), ..., 1] = weight * np.sin(phase)
        self._last_time_us: int | None = None

    def sample(self, truth: VehicleTruth) -> ImuSample:
        """One IMU reading of ``truth`` (call at ``rate_hz`` for the stated noise)."""
        now = truth.time_us
        dt = 1.0 / self.rate_hz if self._last_time_us is None else (now - self._last_time_us) / 1e6
        self._last_time_us = now
        if dt > 0:
            sqrt_dt = math.sqrt(dt)
            normals = self._normals.take(_kernels.WALK_DRAWS + _kernels.SAMPLE_DRAWS)
        else:
            sqrt_dt = 0.0
            normals = self._normals.take(_kernels.SAMPLE_DRAWS)
        environment = self._environment
        temperature = (
            environment.air_temperature_degc(environment.altitude_amsl_m(truth.position_ned_m))
            + self._imu.self_heating_k
        )
        out = np.empty((_kernels.TRIADS, 3))
        _kernels.imu_sample(
            truth.specific_force_frd_mps2,
            truth.angular_rate_frd_radps,
            truth.rotor_speed_radps,
            truth.rotor_angle_rad,
            self._reference_rotor_speed_radps,
            self._level_speed_radps,
            self._levels,
            sqrt_dt,
            temperature - self._imu.reference_temperature_degc,
            self._triad,
            self._bias,
            self._tone_quadrature,
            normals,
            out,
        )
        return ImuSample(now, out[_kernels.ACCEL], out[_kernels.GYRO], temperature)


class BaroModel:
    """Static pressure (ISA at the vehicle's altitude) with white noise and a drifting offset."""

    def __init__(
        self, vehicle: Vehicle, environment: Environment, rng: np.random.Generator
    ) -> None:
        self._baro = vehicle.baro
        self._environment = environment
        self._normals = NormalBlocks(rng)  # per sample: drift step (when time advanced), noise
        self._drift_pa = 0.0
        self._last_time_us: int | None = None

    def sample(self, truth: VehicleTruth) -> BaroSample:
        baro = self._baro
        now = truth.time_us
        if self._last_time_us is not None and now > self._last_time_us:
            step, noise = self._normals.take(2)
            elapsed_s = (now - self._last_time_us) / 1e6
            self._drift_pa += baro.drift_random_walk_pa_per_sqrts * math.sqrt(elapsed_s) * step
        else:
            (noise,) = self._normals.take(1)
        self._last_time_us = now
        altitude = self._environment.altitude_amsl_m(truth.position_ned_m)
        pressure = (
            self._environment.static_pressure_pa(altitude)
            + self._drift_pa
            + baro.noise_std_pa * noise
        )
        temperature = self._environment.air_temperature_degc(altitude) + baro.self_heating_k
        return BaroSample(now, float(pressure), temperature)


class MagModel:
    """Earth's field rotated into the body, plus the vehicle's hard-iron offset and noise."""

    def __init__(
        self, vehicle: Vehicle, environment: Environment, rng: np.random.Generator
    ) -> None:
        self._mag = vehicle.mag
        self._field_ned = environment.magnetic_field.ned_gauss()
        self._hard_iron = np.asarray(vehicle.mag.hard_iron_frd_gauss, dtype=float)
        self._normals = NormalBlocks(rng)

    def sample(self, truth: VehicleTruth) -> MagSample:
        field = _kernels.mag_sample(
            truth.attitude_quat,
            self._field_ned,
            self._hard_iron,
            self._mag.noise_std_gauss,
            self._normals.take(3),
        )
        return MagSample(truth.time_us, field)


class RangefinderModel:
    """Distance along the beam to the flat ground (NED down = 0): tilt lengthens it by
    1/cos, white noise is added, and past the range or tilt limit there is no return.

    Nothing is quantized here: the chip reports whole centimetres
    (``fpga_hdl.chips.lidarlite.driver.sample_from_range``). One normal draw per sample,
    returned or not, so a no-return never shifts the later numbers.
    """

    def __init__(self, params: RangefinderParams, rng: np.random.Generator) -> None:
        self._params = params
        self._axis_frd = np.array(params.axis_frd)
        self._position_frd = np.array(params.position_frd_m)
        self._min_cos_tilt = math.cos(math.radians(params.max_tilt_deg))
        self._normals = NormalBlocks(rng, block_size=256)

    def true_range_m(self, truth: VehicleTruth) -> float | None:
        """The noiseless range, or None when the beam gets no return."""
        q = truth.attitude_quat
        cos_tilt = float(body_to_ned(q, self._axis_frd)[2])
        if cos_tilt < self._min_cos_tilt:
            return None
        height_m = -float(truth.position_ned_m[2] + body_to_ned(q, self._position_frd)[2])
        distance = max(height_m, 0.0) / cos_tilt
        return None if distance > self._params.max_range_m else distance

    def sample(self, truth: VehicleTruth) -> RangeSample:
        (noise,) = self._normals.take(1)
        distance = self.true_range_m(truth)
        if distance is not None:
            distance = max(distance + self._params.noise_std_m * float(noise), 0.0)
        return RangeSample(truth.time_us, distance)


class OpticalFlowModel:
    """A downward optical-flow camera over the flat ground (NED down = 0).

    Called every rig frame, it integrates the ground's image motion as seen along the
    camera axis: the vehicle's body rate (the whole image turns with it) less the camera's
    velocity over the range r to the ground along that axis (about x: rate_x - v_y/r, about
    y: rate_y + v_x/r, body axes, the mount's lever arm included), the model
    PX4's EKF2 predicts flow with. Each camera frame (``frame_rate_hz``) it returns the
    frame's motion with white noise; beyond ``max_rate_radps`` the motion saturates there.

    Quality (SQUAL) is ``squal_max`` scaled by the surface's texture, by the light below
    ``full_exposure_lux`` and by motion blur (pixels smeared over the exposure, which
    lengthens as the light falls, up to one frame); the noise grows as texture and light
    fall. Out of focus (nearer than ``min_range_m``) or tilted past ``max_tilt_deg`` the
    camera sees no features: SQUAL 0 and no motion. Nothing is quantized here: the chip
    counts whole counts (the rig converts). Two normal draws per frame, whatever is seen.
    """

    def __init__(
        self, params: OpticalFlowParams, surface: Surface, rng: np.random.Generator
    ) -> None:
        self._params = params
        self._position_frd = np.array(params.position_frd_m)
        self._min_cos_tilt = math.cos(math.radians(params.max_tilt_deg))
        frame_s = 1.0 / params.frame_rate_hz
        light = min(surface.illuminance_lux / params.full_exposure_lux, 1.0)
        #: Auto-exposure: inversely with the light, never longer than a frame.
        self.exposure_s = frame_s if light < 1.0 else frame_s * params.full_exposure_lux / max(
            surface.illuminance_lux, 1e-9)  # fmt: skip
        self._squal_scale = params.squal_max * surface.texture * light
        seen = max(surface.texture * light, 1e-4)
        self._noise_std_rad = params.noise_std_rad / math.sqrt(seen)
        self._due = _Due(params.frame_rate_hz)
        self._normals = NormalBlocks(rng, block_size=256)
        self._motion_rad = np.zeros(2)
        self._peak_rate_radps = 0.0
        self._blind = False
        self._last_us: int | None = None
        self._frame_start_us = 0

    def image_rate(self, truth: VehicleTruth) -> NDArray[np.float64] | None:
        """The ground image's angular rate about body x, y (rad/s); None when unseen."""
        q = truth.attitude_quat
        cos_tilt = float(body_to_ned(q, np.array((0.0, 0.0, 1.0)))[2])
        if cos_tilt < self._min_cos_tilt:
            return None
        mount_ned = body_to_ned(q, self._position_frd)
        range_m = -float(truth.position_ned_m[2] + mount_ned[2]) / cos_tilt
        if range_m < self._params.min_range_m:
            return None
        rate = truth.angular_rate_frd_radps
        velocity_ned = truth.velocity_ned_mps + body_to_ned(q, np.cross(rate, self._position_frd))
        v = ned_to_body(q, velocity_ned)
        return np.array((rate[0] - v[1] / range_m, rate[1] + v[0] / range_m))

    def sample(self, truth: VehicleTruth) -> FlowSample | None:
        """Integrate up to ``truth``'s time; at a frame's end, the frame."""
        now = truth.time_us
        dt = 0.0 if self._last_us is None else (now - self._last_us) / 1e6
        self._last_us = now
        image_rate = self.image_rate(truth)
        if image_rate is None:
            self._blind = True
        else:
            self._motion_rad += image_rate * dt
            self._peak_rate_radps = max(self._peak_rate_radps, float(np.hypot(*image_rate)))
        if not self._due(now):
            return None
        noise = self._normals.take(2)
        motion, peak, blind = self._motion_rad, self._peak_rate_radps, self._blind
        frame_start_us, self._frame_start_us = self._frame_start_us, now
        self._motion_rad, self._peak_rate_radps, self._blind = np.zeros(2), 0.0, False
        params = self._params
        blur_px = peak * self.exposure_s / params.pixel_rad
        squal = 0 if blind else round(self._squal_scale / (1.0 + blur_px**2))
        if squal <= 0:
            return FlowSample(now, (0.0, 0.0), 0, self.exposure_s)
        limit = params.max_rate_radps * (now - frame_start_us) / 1e6
        size = float(np.hypot(*motion))
        if size > limit:  # the chip's search window: faster motion reads as its limit
            motion = motion * (limit / size)
        measured = motion + self._noise_std_rad * noise
        return FlowSample(now, (float(measured[0]), float(measured[1])), min(squal, 255),
                          self.exposure_s)  # fmt: skip


class GpsModel:
    """GNSS receiver: Gauss-Markov position error, velocity noise, latency, fix rate.

    Call :meth:`sample` every rig frame: it keeps the recent truth and returns a fix when
    one is due (epochs every 1/fix_rate s, each output ``latency_s`` after its epoch),
    otherwise None. Latency resolves to the calling period. Draws: the initial position
    error, then per fix the position error's innovation and the velocity noise.

    ``fix_rate_hz`` is the receiver's *maximum* navigation rate (a NEO-M8N: 10 Hz with
    concurrent GNSS), the finest grid of epochs it can report. Which of them it does report
    is its configuration's: the emulated u-blox keeps those whose time of week (the
    sample's ``epoch_us``) its CFG-RATE measRate divides, so PX4's 200 ms gives 5 Hz.
    """

    def __init__(
        self, vehicle: Vehicle, environment: Environment, rng: np.random.Generator
    ) -> None:
        self._gps = vehicle.gps
        self._home = environment.home
        gps = self._gps
        self._period_s = 1.0 / gps.fix_rate_hz
        self._error_std = np.array(
            [gps.horizontal_error_std_m, gps.horizontal_error_std_m, gps.vertical_error_std_m]
        )
        self._error_m = self._error_std * rng.standard_normal(3)
        self._normals = NormalBlocks(rng)
        self._epochs = SlotGrid(gps.fix_rate_hz)
        self._latency_us = round(gps.latency_s * 1e6)
        self._next_epoch = 0  # the epoch whose fix is output next
        self._next_output_us = self._latency_us
        # Truths are read-only snapshots: keeping them is cheaper than copying two vectors.
        self._history: deque[VehicleTruth] = deque()

    def sample(self, truth: VehicleTruth) -> GpsSample | None:
        self._history.append(truth)
        now = truth.time_us
        if now < self._next_output_us:
            return None
        gps = self._gps
        # The latest epoch whose fix is out by now (later than the next one if the caller
        # was slower than the fix rate: the missed fixes are skipped).
        epoch = max(self._next_epoch, self._epochs.slot_at(now - self._latency_us))
        epoch_us = self._epochs.time_of(epoch)
        self._next_epoch = epoch + 1
        self._next_output_us = self._epochs.time_of(epoch + 1) + self._latency_us
        history = self._history
        while len(history) > 1 and history[1].time_us <= epoch_us:
            history.popleft()
        at_epoch = history[0]
        decay = math.exp(-self._period_s / gps.error_correlation_time_s)
        self._error_m = self._error_m * decay + self._error_std * math.sqrt(
            1.0 - decay * decay
        ) * self._normals.take(3)
        lat, lon, alt = ned_to_geodetic(
            at_epoch.position_ned_m + self._error_m,
            self._home.lat_deg,
            self._home.lon_deg,
            self._home.alt_amsl_m,
        )
        velocity = at_epoch.velocity_ned_mps + gps.velocity_noise_std_mps * self._normals.take(3)
        return GpsSample(
            time_us=now,
            epoch_us=epoch_us,
            lat_deg=lat,
            lon_deg=lon,
            alt_amsl_m=alt,
            vel_ned_mps=velocity,
            eph_m=gps.horizontal_error_std_m,
            epv_m=gps.vertical_error_std_m,
            fix_type=GPS_FIX_3D,
            satellites_visible=gps.satellites_visible,
        )


class SlotGrid:
    """Sampling slots k = 0, 1, 2, … at ⌈k·10⁶/rate⌉ µs, in whole numbers.

    Integer arithmetic on the rate as an exact fraction: a float grid drifts (at 250 Hz an
    IMU slot was once missed after 575 s), this one stays on its slots for ever.
    """

    __slots__ = ("_den", "_num")

    def __init__(self, rate_hz: float) -> None:
        rate = Fraction(rate_hz)  # a float's exact value
        self._num, self._den = rate.numerator, rate.denominator  # rate = num/den Hz

    def slot_at(self, time_us: int) -> int:
        """The last slot at or before ``time_us`` (-1 before slot 0)."""
        return (time_us * self._num) // (1_000_000 * self._den)

    def time_of(self, slot: int) -> int:
        """When slot ``slot`` is due (µs)."""
        return -(-slot * 1_000_000 * self._den // self._num)


class _Due:
    """Due once the time reaches the grid's next slot; a late call skips the slots missed."""

    __slots__ = ("_grid", "_next_us")

    def __init__(self, rate_hz: float) -> None:
        self._grid = SlotGrid(rate_hz)
        self._next_us = 0

    def __call__(self, time_us: int) -> bool:
        if time_us < self._next_us:
            return False
        self._next_us = self._grid.time_of(self._grid.slot_at(time_us) + 1)
        return True


@dataclass(frozen=True)
class SensorReadings:
    """What the sensors produced at one rig frame; None where a sensor was not due."""

    imu: ImuSample | None
    mag: MagSample | None
    baro: BaroSample | None
    gps: GpsSample | None
    range: RangeSample | None = None
    flow: FlowSample | None = None


class SensorSuite:
    """All the sensors of a vehicle on their own schedules (the rig calls it each frame).

    A sensor is due when the frame time reaches its next slot on a fixed grid k/rate, so
    rates that do not divide the frame rate keep their long-run average. The rangefinder
    samples only when a ``rangefinder_rate_hz`` is given (the vehicle must carry one); its
    generator is the fifth spawned, so the other four draw the same numbers either way. The
    optical-flow camera, when ``optical_flow`` (the vehicle must carry one), integrates every
    frame and is the sixth. Without ``gps`` the vehicle has no receiver.
    """

    def __init__(
        self,
        vehicle: Vehicle,
        environment: Environment,
        rng: np.random.Generator,
        imu_rate_hz: float = DEFAULT_IMU_RATE_HZ,
        mag_rate_hz: float = DEFAULT_MAG_RATE_HZ,
        baro_rate_hz: float = DEFAULT_BARO_RATE_HZ,
        rangefinder_rate_hz: float | None = None,
        optical_flow: bool = False,
        gps: bool = True,
    ) -> None:
        imu_rng, mag_rng, baro_rng, gps_rng, range_rng, flow_rng = rng.spawn(6)
        self.imu = ImuModel(vehicle, environment, imu_rng, imu_rate_hz)
        self.mag = MagModel(vehicle, environment, mag_rng)
        self.baro = BaroModel(vehicle, environment, baro_rng)
        #: None: the vehicle flies without a receiver (its generator is spawned all the same).
        self.gps = GpsModel(vehicle, environment, gps_rng) if gps else None
        self._imu_due = _Due(self.imu.rate_hz)
        self._mag_due = _Due(_check_rate(mag_rate_hz, "mag_rate_hz"))
        self._baro_due = _Due(_check_rate(baro_rate_hz, "baro_rate_hz"))
        self.rangefinder: RangefinderModel | None = None
        if rangefinder_rate_hz is not None:
            if vehicle.rangefinder is None:
                raise SensorConfigError(f"vehicle {vehicle.name!r} has no [rangefinder] table")
            self.rangefinder = RangefinderModel(vehicle.rangefinder, range_rng)
            self._range_due = _Due(_check_rate(rangefinder_rate_hz, "rangefinder_rate_hz"))
        self.optical_flow: OpticalFlowModel | None = None
        if optical_flow:
            if vehicle.optical_flow is None:
                raise SensorConfigError(f"vehicle {vehicle.name!r} has no [optical_flow] table")
            self.optical_flow = OpticalFlowModel(
                vehicle.optical_flow, environment.surface, flow_rng
            )

    def sample(self, truth: VehicleTruth) -> SensorReadings:
        t = truth.time_us
        return SensorReadings(
            self.imu.sample(truth) if self._imu_due(t) else None,
            self.mag.sample(truth) if self._mag_due(t) else None,
            self.baro.sample(truth) if self._baro_due(t) else None,
            None if self.gps is None else self.gps.sample(truth),
            None
            if self.rangefinder is None or not self._range_due(t)
            else self.rangefinder.sample(truth),
            None if self.optical_flow is None else self.optical_flow.sample(truth),
        )


__all__ = [
    "BaroModel",
    "BaroSample",
    "FlowSample",
    "GpsModel",
    "GpsSample",
    "ImuModel",
    "ImuSample",
    "MagModel",
    "MagSample",
    "NormalBlocks",
    "OpticalFlowModel",
    "RangeSample",
    "RangefinderModel",
    "SensorConfigError",
    "SensorReadings",
    "SensorSuite",
    "SlotGrid",
]
