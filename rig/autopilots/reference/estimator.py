"""State estimation from the sensors alone: attitude, then position and velocity.

Ground truth never enters here; the flight controller compares against it only to log the
estimator's errors.

- :class:`AttitudeEstimator`: PX4's quaternion complementary filter (``attitude_estimator_q``,
  parameters ``ATT_*``): gyro integration corrected towards gravity by the accelerometer and
  towards magnetic north by the magnetometer's horizontal component, with a gyro-bias
  integrator and acceleration compensation.
- :class:`PositionEstimator`: a linear Kalman filter in the local NED frame, predicting with
  the accelerometer rotated to NED, corrected by GPS position/velocity and barometric height
  (noise figures under PX4's ``EKF2_*`` names), and near the ground by a rangefinder
  (PX4's conditional range aid). With the attitude given, the model is linear
  and the three axes decouple, so it runs as three 3-state filters (position, velocity,
  accelerometer bias) updated together in numpy.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numba import njit
from numpy.typing import NDArray

from quad_model import frames
from quad_model.frames import STANDARD_GRAVITY_MPS2, cross3, quat_from_dcm, quat_multiply, yaw_quat
from rig.autopilots.reference.params import Parameters

#: PX4 holds the gyro bias while rotating faster than this (attitude_estimator_q: 0.175 rad/s).
_BIAS_LEARN_MAX_RATE_RADPS = 0.175
#: Above 50 °/s PX4 raises the magnetometer weight with the spin rate (at most ×10).
_MAG_SPIN_RATE_RADPS = 0.873
#: Innovations beyond this many standard deviations are rejected (PX4 EKF2_*_GATE = 5).
_GATE_SIGMA = 5.0
_NAN3 = np.full(3, np.nan)
#: ISA troposphere constants for barometric altitude (ICAO Doc 7488).
_ISA_P0_PA, _ISA_T0_K, _ISA_LAPSE_KPM, _ISA_EXPONENT = 101325.0, 288.15, 0.0065, 0.190263


def pressure_altitude_m(pressure_pa: float) -> float:
    """ISA altitude of a static pressure: how PX4 turns the barometer into a height."""
    return _ISA_T0_K / _ISA_LAPSE_KPM * (1.0 - (pressure_pa / _ISA_P0_PA) ** _ISA_EXPONENT)


_quat_to_dcm = njit(cache=True)(frames.quat_to_dcm)


@njit(cache=True)
def _wrap_pi(angle_rad: float) -> float:
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True)
def _attitude_step(
    q: np.ndarray,
    bias: np.ndarray,
    rates: np.ndarray,
    gyro: np.ndarray,
    accel: np.ndarray,
    mag: np.ndarray,
    accel_ned: np.ndarray,
    dt: float,
    gains: np.ndarray,
    declination_rad: float,
) -> None:
    """One complementary-filter step on ``q``, ``bias`` and ``rates`` in place.

    Compiled: it runs every IMU frame, and in numpy its two dozen small-array operations
    cost ~35 µs, here ~1 µs. ``mag`` or ``accel_ned`` all-NaN means not available;
    ``gains`` is (ATT_W_ACC, ATT_W_MAG, ATT_W_GYRO_BIAS, ATT_BIAS_MAX).
    """
    w_acc, w_mag, w_bias, bias_max = gains[0], gains[1], gains[2], gains[3]
    r = _quat_to_dcm(q)
    spin = math.sqrt(gyro[0] ** 2 + gyro[1] ** 2 + gyro[2] ** 2)
    correction = np.zeros(3)
    if not math.isnan(mag[0]) and w_mag > 0.0:
        mag_ned = r @ mag
        heading_error = _wrap_pi(math.atan2(mag_ned[1], mag_ned[0]) - declination_rad)
        gain = w_mag * min(max(spin / _MAG_SPIN_RATE_RADPS, 1.0), 10.0)
        correction += r[2] * (-heading_error * gain)  # NED down axis in body = row 2 of R
    gravity = accel.copy()
    if not math.isnan(accel_ned[0]):
        for i in range(3):  # minus Rᵀ·accel_ned
            gravity[i] -= r[0, i] * accel_ned[0] + r[1, i] * accel_ned[1] + r[2, i] * accel_ned[2]
    norm = math.sqrt(gravity[0] ** 2 + gravity[1] ** 2 + gravity[2] ** 2)
    if norm > 1e-3:
        correction += np.cross(r[2], gravity / norm) * w_acc
    if spin < _BIAS_LEARN_MAX_RATE_RADPS:
        for i in range(3):
            bias[i] = min(max(bias[i] - correction[i] * (w_bias * dt), -bias_max), bias_max)
    for i in range(3):
        rates[i] = gyro[i] - bias[i]
    omega = (rates + correction) * (0.5 * dt)
    w, x, y, z = q[0], q[1], q[2], q[3]
    q[0] = w - x * omega[0] - y * omega[1] - z * omega[2]
    q[1] = x + w * omega[0] + y * omega[2] - z * omega[1]
    q[2] = y + w * omega[1] - x * omega[2] + z * omega[0]
    q[3] = z + w * omega[2] + x * omega[1] - y * omega[0]
    q /= math.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2 + q[3] ** 2)


@njit(cache=True)
def _predict_step(
    x: np.ndarray,
    p: np.ndarray,
    transition: np.ndarray,
    transition_t: np.ndarray,
    process_noise: np.ndarray,
    specific_force_ned: np.ndarray,
    dt: float,
) -> np.ndarray:
    """Kalman prediction of the three per-axis (position, velocity, error) filters in place.

    Compiled for the same reason as :func:`_attitude_step` (~15 µs in numpy, ~1 µs here).
    Returns the bias-corrected NED acceleration.
    """
    accel = specific_force_ned.copy()
    accel[2] += STANDARD_GRAVITY_MPS2
    for axis in range(3):
        x[axis] = transition @ x[axis]
        x[axis, 0] += 0.5 * dt * dt * accel[axis]
        x[axis, 1] += dt * accel[axis]
        p[axis] = transition @ p[axis] @ transition_t + process_noise[axis]
        accel[axis] -= x[axis, 2]
    return accel


class AttitudeEstimator:
    """Quaternion complementary filter with gyro bias, as PX4's ``attitude_estimator_q``.

    The quaternion rotates body (FRD) vectors into NED. ``gyro_bias_radps`` is the sensor's
    bias (``rates = gyro - bias``).
    """

    def __init__(self) -> None:
        self.w_acc = 0.2
        self.w_mag = 0.1
        self.w_gyro_bias = 0.1
        self.bias_max_radps = 0.05
        self.declination_rad = 0.0
        self.reset()

    def configure(self, params: Parameters) -> None:
        self.w_acc, self.w_mag = params["ATT_W_ACC"], params["ATT_W_MAG"]
        self.w_gyro_bias, self.bias_max_radps = params["ATT_W_GYRO_BIAS"], params["ATT_BIAS_MAX"]

    def reset(self) -> None:
        self.q = np.array([1.0, 0.0, 0.0, 0.0])
        self.gyro_bias_radps = np.zeros(3)
        self.rates_radps = np.zeros(3)
        self.initialized = False

    def set_declination(self, declination_rad: float) -> None:
        """Change the declination; an initialized estimate is rotated with it at once, as PX4
        does, so the bias integrator never sees a heading step."""
        if self.initialized:
            self.q = quat_multiply(yaw_quat(declination_rad - self.declination_rad), self.q)
        self.declination_rad = declination_rad

    def initialize(
        self, accel_mps2: NDArray[np.float64], mag_gauss: NDArray[np.float64] | None
    ) -> None:
        """Level from gravity and heading from the field (north = 0 without a magnetometer)."""
        down = -accel_mps2 / np.linalg.norm(accel_mps2)
        reference = mag_gauss if mag_gauss is not None else np.array([1.0, 0.0, 0.0])
        north = reference - down * float(reference @ down)
        if np.linalg.norm(north) < 1e-6:  # field along gravity: take body x for north
            north = np.array([1.0, 0.0, 0.0]) - down * down[0]
        north /= np.linalg.norm(north)
        east = cross3(down, north)
        q = quat_from_dcm(np.vstack([north, east, down]))
        self.q = quat_multiply(yaw_quat(self.declination_rad), q)
        self.initialized = True

    def update(
        self,
        gyro_radps: NDArray[np.float64],
        accel_mps2: NDArray[np.float64],
        mag_gauss: NDArray[np.float64] | None,
        dt_s: float,
        accel_ned_mps2: NDArray[np.float64] | None = None,
    ) -> None:
        """One filter step; ``accel_ned_mps2`` (the vehicle's own acceleration) is removed from
        the accelerometer so that only gravity pulls the tilt."""
        if not self.initialized:
            self.initialize(accel_mps2, mag_gauss)
        gains = np.array([self.w_acc, self.w_mag, self.w_gyro_bias, self.bias_max_radps])
        _attitude_step(
            self.q, self.gyro_bias_radps, self.rates_radps, np.asarray(gyro_radps, dtype=float),
            np.asarray(accel_mps2, dtype=float),
            _NAN3 if mag_gauss is None else np.asarray(mag_gauss, dtype=float),
            _NAN3 if accel_ned_mps2 is None else np.asarray(accel_ned_mps2, dtype=float),
            dt_s, gains, self.declination_rad,
        )  # fmt: skip


class GyroRestCalibration:
    """Gyro offsets measured while the vehicle sits still, as PX4's ``gyro_calibration``
    module does when disarmed: the complementary filter alone needs tens of seconds to learn
    a bias, and until then leaves a tilt error of bias/ATT_W_ACC.

    Samples are averaged over windows of ``window_s``; a window counts only when every axis
    stays within ``max_std_radps`` of its mean and the accelerometer reads 1 g within
    ``accel_tolerance_mps2`` (nothing is moving).
    """

    def __init__(self, window_s: float = 1.0, max_std_radps: float = 0.02,
                 accel_tolerance_mps2: float = 0.5) -> None:  # fmt: skip
        self.window_s = window_s
        self.max_std_radps = max_std_radps
        self.accel_tolerance_mps2 = accel_tolerance_mps2
        self.reset()

    def reset(self) -> None:
        self._sum = np.zeros(3)
        self._sum_sq = np.zeros(3)
        self._elapsed_s = 0.0
        self._count = 0
        self._moving = False

    def update(
        self, gyro_radps: NDArray[np.float64], accel_mps2: NDArray[np.float64], dt_s: float
    ) -> NDArray[np.float64] | None:
        """Add one sample; returns the window's mean gyro when a still window completes."""
        if (
            abs(float(np.linalg.norm(accel_mps2)) - STANDARD_GRAVITY_MPS2)
            > self.accel_tolerance_mps2
        ):
            self._moving = True
        self._sum += gyro_radps
        self._sum_sq += gyro_radps * gyro_radps
        self._count += 1
        self._elapsed_s += dt_s
        if self._elapsed_s < self.window_s:
            return None
        mean = self._sum / self._count
        std = np.sqrt(np.maximum(self._sum_sq / self._count - mean * mean, 0.0))
        still = not self._moving and bool((std < self.max_std_radps).all())
        self.reset()
        return mean if still else None


#: EKF2's process noise of the barometer's bias (m/s/√Hz, ``baro_bias_nsd``).
_BARO_BIAS_NSD = 0.13


class PositionEstimator:
    """Local NED position and velocity from accelerometer, GPS and barometer.

    The state per axis is (position m, velocity m/s, NED acceleration error m/s²). The
    origin is set at the first GPS fix good enough (``EKF2_REQ_*``); height starts at the
    first baro sample (its reference below).

    Process noise as PX4's EKF2 has it, whatever the IMU rate. EKF2 predicts every
    ``EKF2_PREDICT_US`` (10 ms) with a velocity variance of ``(Δt·EKF2_ACC_NOISE)²`` per
    step; predicting every IMU sample, the same variance per second is
    ``dt·Δt·EKF2_ACC_NOISE²`` per sample (with ``dt²`` instead, the filter at 1 kHz trusted
    its prediction ten times more than EKF2 and took ~12 s to follow GPS). And the
    horizontal acceleration error holds the attitude's tilt error times g, not only the
    accelerometer's bias: EKF2 estimates tilt with velocity, and its tilt variance grows
    with ``EKF2_GYR_NOISE``; here that growth, times g, is the horizontal error state's
    process noise. Without it a tilt error left by a manoeuvre (0.015 rad after the demo's
    5 m step) was learnt at the bias's 0.003 m/s³ and the estimate sat 0.5-0.8 m short of
    the GPS for 15 s.

    Height is the GPS's when ``EKF2_HGT_REF`` is 1 (PX4's default), the barometer's
    otherwise. With GPS as the reference the barometer still smooths the height, less its
    bias, which a one-state filter learns from the difference of the two as EKF2's does
    (``baro_height_control.cpp``: process noise 0.13 m/s/√Hz); the barometer alone as the
    reference let its drift through (0.43 m over the demo).

    GPS is fused where it was measured, ``EKF2_GPS_DELAY`` ago: its innovation is taken
    against the estimate of that moment (kept for the delay), and the correction applied
    now, as EKF2's delayed fusion horizon does. Against the latest estimate, a fix 110 ms
    old pulled a vehicle moving at 3 m/s 0.3 m back and the hold after a step swung.
    """

    def __init__(self) -> None:
        self.acc_noise = 0.35
        self.acc_bias_noise = 0.003
        self.tilt_noise_mps2 = STANDARD_GRAVITY_MPS2 * 0.015
        self.predict_period_s = 0.01
        self.gps_delay_s = 0.11
        self.gps_height_reference = True
        self.gps_pos_noise_m = 0.5
        self.gps_vel_noise_mps = 0.3
        self.baro_noise_m = 3.5
        self.range_noise_m = 0.1
        self.rejected = 0
        self._dt_cached = -1.0
        self.reset()

    def configure(self, params: Parameters) -> None:
        self.acc_noise, self.acc_bias_noise = params["EKF2_ACC_NOISE"], params["EKF2_ACC_B_NOISE"]
        self.tilt_noise_mps2 = STANDARD_GRAVITY_MPS2 * params["EKF2_GYR_NOISE"]
        self.predict_period_s = params["EKF2_PREDICT_US"] * 1e-6
        self.gps_delay_s = params["EKF2_GPS_DELAY"] * 1e-3
        self.gps_height_reference = params["EKF2_HGT_REF"] == 1
        self.gps_pos_noise_m = params["EKF2_GPS_P_NOISE"]
        self.gps_vel_noise_mps = params["EKF2_GPS_V_NOISE"]
        self.baro_noise_m = params["EKF2_BARO_NOISE"]
        self.range_noise_m = params["EKF2_RNG_NOISE"]
        self._dt_cached = -1.0

    def reset(self) -> None:
        self.x = np.zeros((3, 3))  # [axis N/E/D, (pos, vel, bias)]
        self.p = np.tile(np.diag([100.0, 4.0, 0.1]), (3, 1, 1))
        self.accel_ned_mps2 = np.zeros(3)
        self.origin: tuple[float, float, float] | None = None  # lat, lon deg; alt AMSL m
        self.origin_time_us = 0
        self.baro_reference_m: float | None = None
        #: The barometer's height error (m, positive: it reads low) and its variance.
        self.baro_bias_m = 0.0
        self.baro_bias_var = self.baro_noise_m**2
        self._baro_clock_s = 0.0
        #: NED down of the (flat) ground under a rangefinder; None before a reading.
        self.ground_down_m: float | None = None
        #: (clock s, position, velocity) of the estimates over the last GPS delay, for GPS
        #: fusion; the clock counts predicted time.
        self._recent: deque[tuple[float, NDArray[np.float64], NDArray[np.float64]]] = deque()
        self._clock_s = 0.0

    @property
    def position_ned_m(self) -> NDArray[np.float64]:
        return self.x[:, 0]

    @property
    def velocity_ned_mps(self) -> NDArray[np.float64]:
        return self.x[:, 1]

    @property
    def accel_bias_ned_mps2(self) -> NDArray[np.float64]:
        return self.x[:, 2]

    @property
    def position_std_m(self) -> NDArray[np.float64]:
        return np.sqrt(self.p[:, 0, 0])

    @property
    def velocity_std_mps(self) -> NDArray[np.float64]:
        return np.sqrt(self.p[:, 1, 1])

    def predict(self, specific_force_ned_mps2: NDArray[np.float64], dt_s: float) -> None:
        """Propagate with the accelerometer (already rotated to NED)."""
        if dt_s != self._dt_cached:
            self._transition = np.array([[1.0, dt_s, -0.5 * dt_s**2], [0.0, 1.0, -dt_s], [0, 0, 1]])
            self._transition_t = np.ascontiguousarray(self._transition.T)
            g = np.array([0.5 * dt_s**2, dt_s, 0.0])
            velocity_variance = np.outer(g, g) * (self.predict_period_s / dt_s) * self.acc_noise**2
            error_variance = np.array([self.acc_bias_noise**2 + self.tilt_noise_mps2**2] * 2
                                      + [self.acc_bias_noise**2]) * dt_s  # fmt: skip
            self._process_noise = np.repeat(velocity_variance[None], 3, axis=0)
            self._process_noise[:, 2, 2] = error_variance
            self._dt_cached = dt_s
        self.accel_ned_mps2 = _predict_step(
            self.x, self.p, self._transition, self._transition_t, self._process_noise,
            np.asarray(specific_force_ned_mps2, dtype=float), dt_s,
        )  # fmt: skip
        self._clock_s += dt_s
        recent = self._recent
        recent.append((self._clock_s, self.x[:, 0].copy(), self.x[:, 1].copy()))
        while len(recent) > 1 and recent[1][0] <= self._clock_s - self.gps_delay_s:
            recent.popleft()

    def fuse_gps(
        self,
        position_ned_m: NDArray[np.float64],
        velocity_ned_mps: NDArray[np.float64],
        use_height: bool,
    ) -> None:
        """GPS position (horizontal, plus height with ``use_height``: GPS is the height
        reference, or the barometer is out) and velocity, measured ``gps_delay_s`` ago."""
        # The change of the estimate since the fix was measured, added to the fix.
        if self._recent:
            _, position_then, velocity_then = self._recent[0]
            position_ned_m = position_ned_m + (self.x[:, 0] - position_then)
            velocity_ned_mps = velocity_ned_mps + (self.x[:, 1] - velocity_then)
        self._fuse(slice(0, 2), 0, position_ned_m[:2], self.gps_pos_noise_m**2)
        if use_height:  # EKF2: 1.5 times the horizontal noise, a typical vacc/hacc
            self._fuse(slice(2, 3), 0, position_ned_m[2:], (1.5 * self.gps_pos_noise_m) ** 2)
        self._fuse(slice(0, 3), 1, velocity_ned_mps, self.gps_vel_noise_mps**2)

    def fuse_baro(self, altitude_m: float, learn_bias: bool = False) -> None:
        """A barometric altitude; ``learn_bias`` while another height (GPS) is fused."""
        if self.baro_reference_m is None:
            self.baro_reference_m = altitude_m + self.x[2, 0]
        down = self.baro_reference_m - altitude_m
        noise_var = self.baro_noise_m**2
        innovation_down = down - self.baro_bias_m
        if learn_bias:
            elapsed_s = self._clock_s - self._baro_clock_s
            self.baro_bias_var = min(self.baro_bias_var + _BARO_BIAS_NSD**2 * elapsed_s, noise_var)
            gain = self.baro_bias_var / (self.baro_bias_var + noise_var + self.p[2, 0, 0])
            self.baro_bias_m += gain * (down - self.x[2, 0] - self.baro_bias_m)
            self.baro_bias_var *= 1.0 - gain
        self._baro_clock_s = self._clock_s
        self._fuse(slice(2, 3), 0, np.array([innovation_down]), noise_var + self.baro_bias_var)

    def fuse_range(self, dist_bottom_m: float, aid: bool) -> None:
        """A rangefinder's height above the ground. Until the aid applies (PX4's conditions,
        judged by the caller) it only places the ground under the estimate; while it does,
        the range measures the height below that ground, as PX4 EKF2 fuses it near the
        ground on a flat field."""
        if not aid or self.ground_down_m is None:
            self.ground_down_m = float(self.x[2, 0]) + dist_bottom_m
            return
        down = self.ground_down_m - dist_bottom_m
        self._fuse(slice(2, 3), 0, np.array([down]), self.range_noise_m**2)

    def set_origin(self, lat_deg: float, lon_deg: float, alt_amsl_m: float, time_us: int,
                   velocity_ned_mps: NDArray[np.float64]) -> None:  # fmt: skip
        """Start the horizontal frame here; height keeps its baro reference."""
        self.origin = (lat_deg, lon_deg, alt_amsl_m + float(self.x[2, 0]))
        self.origin_time_us = time_us
        self._recent.clear()  # estimates of the old frame
        self.x[:2, 0] = 0.0
        self.x[:, 1] = velocity_ned_mps
        # A reset state loses its correlations: keeping the height's correlation with a
        # replaced vertical velocity left P indefinite once a rangefinder had tightened it.
        self.p[:, 1, :] = self.p[:, :, 1] = 0.0
        self.p[:, 1, 1] = self.gps_vel_noise_mps**2
        self.p[:2, 0, :] = self.p[:2, :, 0] = 0.0
        self.p[:2, 0, 0] = self.gps_pos_noise_m**2

    def _fuse(
        self, axes: slice, state: int, measured: NDArray[np.float64], variance: float
    ) -> None:
        """Scalar Kalman update of one state on several axes at once, with a 5σ gate."""
        p, x = self.p[axes], self.x[axes]
        innovation_var = p[:, state, state] + variance
        innovation = measured - x[:, state]
        accept = innovation**2 <= _GATE_SIGMA**2 * innovation_var
        self.rejected += int(np.count_nonzero(~accept))
        gain = p[:, :, state] / innovation_var[:, None] * accept[:, None]
        x += gain * innovation[:, None]
        p -= gain[:, :, None] * p[:, state, None, :]


class DistanceToGround:
    """Height above the ground below the vehicle from a downward rangefinder: PX4 EKF2's
    ``dist_bottom`` when a rangefinder is fitted (``EKF2_RNG_CTRL`` not 0).

    A reading counts as PX4's ``SensorRangeFinder`` judges it: within the sensor's
    (inclusive) min..max, quality not 0, the beam within 45° of vertical, and no older than
    :data:`RANGE_TIMEOUT_US`. The height is the range times the cosine of the tilt (the
    beam along the body's z axis). It is not fused into the height estimate: the autopilot
    uses it where PX4 uses ``dist_bottom``, the landing speed and the land detector.
    """

    #: PX4 ``SensorRangeFinder``: readings from a beam tilted further are not used.
    COS_MAX_TILT = math.cos(math.radians(45.0))
    #: Four of the LIDAR-Lite's 50 ms cycles without a usable reading end the estimate.
    RANGE_TIMEOUT_US = 200_000

    def __init__(self) -> None:
        self.enabled = True
        self.height_m = math.nan
        self._time_us: int | None = None

    def configure(self, params: Parameters) -> None:
        self.enabled = bool(params["EKF2_RNG_CTRL"])

    def update(self, distance_m: float, signal_quality: int, limits_m: tuple[float, float],
               q: NDArray[np.float64], time_us: int) -> bool:  # fmt: skip
        """A new reading (``q`` the attitude body → NED at that time); True when usable."""
        cos_tilt = float(_quat_to_dcm(q)[2, 2])
        usable = (
            self.enabled
            and limits_m[0] <= distance_m <= limits_m[1]
            and signal_quality != 0
            and cos_tilt > self.COS_MAX_TILT
        )
        if usable:
            self.height_m = distance_m * cos_tilt
            self._time_us = time_us
        return usable

    def valid(self, time_us: int) -> bool:
        """PX4 ``dist_bottom_valid``."""
        return self._time_us is not None and time_us - self._time_us <= self.RANGE_TIMEOUT_US

    def height(self, time_us: int) -> float | None:
        """The height above the ground while valid, else None."""
        return self.height_m if self.valid(time_us) else None
