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
- :class:`OpticalFlowFusion`: EKF2's optical-flow aiding of that filter, for a flight
  without GPS on flow and a rangefinder.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from quad_model import frames
from quad_model.frames import STANDARD_GRAVITY_MPS2, cross3, quat_from_dcm, quat_multiply, yaw_quat
from rig.autopilots.reference.params import Parameters
from rig.autopilots.reference.sensors import FlowReading

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


#: EKF2's longest flow window (s): beyond it, it restarts its gyro accumulation.
FLOW_MAX_WINDOW_S = 0.2
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
        self.flow_delay_s = 0.02
        self.gps_height_reference = True
        self.gps_pos_noise_m = 0.5
        self.gps_vel_noise_mps = 0.3
        self.baro_noise_m = 3.5
        self.range_noise_m = 0.1
        self.rejected = 0
        self._dt_cached = -1.0
        self._kept_s = self._delay_span_s()
        self.reset()

    def configure(self, params: Parameters) -> None:
        self.acc_noise, self.acc_bias_noise = params["EKF2_ACC_NOISE"], params["EKF2_ACC_B_NOISE"]
        self.tilt_noise_mps2 = STANDARD_GRAVITY_MPS2 * params["EKF2_GYR_NOISE"]
        self.predict_period_s = params["EKF2_PREDICT_US"] * 1e-6
        self.gps_delay_s = params["EKF2_GPS_DELAY"] * 1e-3
        self.flow_delay_s = params["EKF2_OF_DELAY"] * 1e-3
        self.gps_height_reference = params["EKF2_HGT_REF"] == 1
        self.gps_pos_noise_m = params["EKF2_GPS_P_NOISE"]
        self.gps_vel_noise_mps = params["EKF2_GPS_V_NOISE"]
        self.baro_noise_m = params["EKF2_BARO_NOISE"]
        self.range_noise_m = params["EKF2_RNG_NOISE"]
        self._dt_cached = -1.0
        self._kept_s = self._delay_span_s()

    def _delay_span_s(self) -> float:
        """How far back delayed fusion looks: the GPS delay, or a flow window's middle."""
        flow_age_s = self.flow_delay_s + 0.5 * (self.predict_period_s + FLOW_MAX_WINDOW_S)
        return max(self.gps_delay_s, flow_age_s)

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
        #: (clock s, position, velocity) of the estimates over the longest measurement delay
        #: (GPS, or a flow window's middle), for delayed fusion; the clock counts predicted time.
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
        while len(recent) > 1 and recent[1][0] <= self._clock_s - self._kept_s:
            recent.popleft()

    def _estimate_ago(self, age_s: float) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
        """Position and velocity estimated ``age_s`` ago (the oldest kept if none is that
        old); None before the first prediction."""
        then = self._clock_s - age_s
        for clock_s, position, velocity in reversed(self._recent):
            if clock_s <= then:
                return position, velocity
        return (self._recent[0][1], self._recent[0][2]) if self._recent else None

    def fuse_gps(
        self,
        position_ned_m: NDArray[np.float64],
        velocity_ned_mps: NDArray[np.float64],
        use_height: bool,
        use_position: bool = True,
        use_velocity: bool = True,
    ) -> None:
        """GPS position (horizontal with ``use_position``, height with ``use_height``: GPS is
        the height reference, or the barometer is out) and velocity (``use_velocity``),
        measured ``gps_delay_s`` ago; the flags are ``EKF2_GPS_CTRL``'s bits."""
        # The change of the estimate since the fix was measured, added to the fix.
        then = self._estimate_ago(self.gps_delay_s)
        if then is not None:
            position_ned_m = position_ned_m + (self.x[:, 0] - then[0])
            velocity_ned_mps = velocity_ned_mps + (self.x[:, 1] - then[1])
        if use_position:
            self._fuse(slice(0, 2), 0, position_ned_m[:2], self.gps_pos_noise_m**2)
        if use_height:  # EKF2: 1.5 times the horizontal noise, a typical vacc/hacc
            self._fuse(slice(2, 3), 0, position_ned_m[2:], (1.5 * self.gps_pos_noise_m) ** 2)
        if use_velocity:
            self._fuse(slice(0, 3), 1, velocity_ned_mps, self.gps_vel_noise_mps**2)

    def fuse_flow(self, los_rate_radps: NDArray[np.float64], range_m: float,
                  r_body_to_ned: NDArray[np.float64], variance: float, age_s: float,
                  gate_sigma: float, lever_velocity_body: NDArray[np.float64]) -> bool:  # fmt: skip
        """Optical flow's line-of-sight rates (rad/s about body x, y, EKF2's sign: positive
        for a right-handed rotation of the scene, gyro already removed) seen over a window
        whose middle was ``age_s`` ago, along a camera axis ``range_m`` from the ground.

        EKF2's model: the rates are the camera's body velocity over the range, (v_y, -v_x)/r,
        the camera's velocity being the vehicle's plus ``lever_velocity_body`` (ω × its
        mount's offset). The innovations and their variances (``variance`` (rad/s)² plus the
        velocity's) are taken in those rates and gated as EKF2 gates them, both axes
        rejected if either fails. With the attitude given, the model is linear in the NED
        velocity; the rates become a horizontal velocity (the vertical from the estimate),
        fused per axis with the noise carried through: exact in level flight, where the axes
        stay uncorrelated as this filter keeps them. Returns whether it was fused.
        """
        then = self._estimate_ago(age_s)
        velocity_then = self.x[:, 1] if then is None else then[1]
        to_body = r_body_to_ned.T
        h = np.array([to_body[1], -to_body[0]]) / range_m  # d(rates)/d(NED velocity)
        lever_los = np.array([lever_velocity_body[1], -lever_velocity_body[0]]) / range_m
        innovation = h @ velocity_then + lever_los - los_rate_radps
        innovation_var = (h * h) @ self.p[:, 1, 1] + variance
        if bool((innovation**2 > gate_sigma**2 * innovation_var).any()):
            self.rejected += 2
            return False
        body_xy = np.array([-los_rate_radps[1], los_rate_radps[0]]) * range_m
        body_xy -= lever_velocity_body[:2]
        horizontal = to_body[:2, :2]
        measured_ne = np.linalg.solve(horizontal, body_xy - to_body[:2, 2] * velocity_then[2])
        inverse = np.linalg.inv(horizontal)
        variance_ne = range_m**2 * variance * (inverse * inverse).sum(axis=1)
        measured_now = self.x[:2, 1] + (measured_ne - velocity_then[:2])
        self._fuse(slice(0, 2), 1, measured_now, variance_ne, gate_sigma=math.inf)
        return True

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
        self._reset(slice(0, 2), 0, np.zeros(2), self.gps_pos_noise_m**2)
        self._reset(slice(0, 3), 1, velocity_ned_mps, self.gps_vel_noise_mps**2)

    def reset_horizontal(
        self,
        position_ne_m: NDArray[np.float64],
        velocity_ne_mps: NDArray[np.float64],
        position_var: float,
        velocity_var: float,
    ) -> None:
        """Put the horizontal position and velocity here, as EKF2 does when an aid starts
        with no other horizontal aid."""
        self._reset(slice(0, 2), 0, position_ne_m, position_var)
        self._reset(slice(0, 2), 1, velocity_ne_mps, velocity_var)

    def _reset(self, axes: slice, state: int, value: NDArray[np.float64], variance: float) -> None:
        """Set one state on some axes, with its variance and no correlations: keeping the
        height's correlation with a replaced vertical velocity left P indefinite once a
        rangefinder had tightened it."""
        self._recent.clear()  # estimates of the old frame
        self.x[axes, state] = value
        self.p[axes, state, :] = self.p[axes, :, state] = 0.0
        self.p[axes, state, state] = variance

    def _fuse(
        self,
        axes: slice,
        state: int,
        measured: NDArray[np.float64],
        variance: float | NDArray[np.float64],
        gate_sigma: float = _GATE_SIGMA,
    ) -> None:
        """Scalar Kalman update of one state on several axes at once (``variance`` one for
        all or one per axis), with a ``gate_sigma`` gate."""
        p, x = self.p[axes], self.x[axes]
        innovation_var = p[:, state, state] + variance
        innovation = measured - x[:, state]
        accept = innovation**2 <= gate_sigma**2 * innovation_var
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


@dataclass(frozen=True)
class FlowVelocity:
    """One flow sample as EKF2 reports it (``estimator_optical_flow_vel``): the velocity it
    gives and its parts over the window, in EKF2's sign (positive for a right-handed rotation
    of the scene; the gyro's the negative of the body's rotation)."""

    time_us: int
    velocity_body_mps: NDArray[np.float64]
    velocity_ne_mps: NDArray[np.float64]
    flow_rad: NDArray[np.float64]
    compensated_rad: NDArray[np.float64]
    gyro_rad: NDArray[np.float64]
    dt_s: float


class OpticalFlowFusion:
    """Optical-flow aiding of the :class:`PositionEstimator`, as PX4 runs it for a flow chip
    without a gyro (a PMW3901): ``VehicleOpticalFlow`` integrates the autopilot's own gyro over
    each flow window, and EKF2 (``optical_flow_control.cpp``, ``optflow_fusion.cpp``) checks,
    compensates and fuses the sample.

    A sample counts when its quality reaches ``EKF2_OF_QMIN`` (``EKF2_OF_QMIN_GND`` on the
    ground), its motion is within ``SENS_FLOW_MAXR`` (the HIL message gives no limit of its
    own), the camera is within 45° of vertical and the gyro covers its window; on the ground
    a sample that fails is taken as no motion (EKF2: zero velocity, on the ground), in the
    air it is dropped. The line-of-sight rate is the flow less the body rotation, fused
    ``EKF2_OF_DELAY`` plus half a window (and half a prediction step) in the past, with
    EKF2's noise between ``EKF2_OF_N_MIN`` and ``EKF2_OF_N_MAX`` by quality and its
    ``EKF2_OF_GATE``; the mount's offset (``EKF2_OF_POS_X/Y/Z``) adds the rotation's
    velocity at the camera. The range along the camera axis is the rangefinder's height over
    the cosine of the tilt, at least ``EKF2_MIN_RNG``.

    Aiding starts with the first good sample; with no other horizontal aid (GPS) the
    horizontal velocity is reset to the flow's and the position to zero on the ground (the
    last known in the air), as EKF2 does. It aids while a sample was fused within
    ``EKF2_NOAID_TOUT``.
    """

    #: EKF2's ``range_cos_max_tilt``: flow from a camera tilted further is not used.
    COS_MAX_TILT = math.cos(math.radians(45.0))
    #: EKF2's position variance after a reset (0.01 m)².
    RESET_POSITION_VAR_M2 = 1e-4

    def __init__(self) -> None:
        self.enabled = True
        self.delay_s = 0.02
        self.predict_period_s = 0.01
        self.quality_min = 1
        self.quality_min_ground = 0
        self.noise_min_radps = 0.15
        self.noise_max_radps = 0.5
        self.gate_sigma = 3.0
        self.max_rate_radps = 8.0
        self.min_range_m = 0.1
        self.no_aid_timeout_us = 5_000_000
        self.position_body_m = np.zeros(3)
        self.reset()

    def configure(self, params: Parameters) -> None:
        self.enabled = bool(params["EKF2_OF_CTRL"])
        self.delay_s = params["EKF2_OF_DELAY"] * 1e-3
        self.predict_period_s = params["EKF2_PREDICT_US"] * 1e-6
        self.quality_min = int(params["EKF2_OF_QMIN"])
        self.quality_min_ground = int(params["EKF2_OF_QMIN_GND"])
        self.noise_min_radps = max(params["EKF2_OF_N_MIN"], 0.05)
        self.noise_max_radps = max(params["EKF2_OF_N_MAX"], 0.05)
        self.gate_sigma = max(params["EKF2_OF_GATE"], 1.0)
        self.max_rate_radps = params["SENS_FLOW_MAXR"]
        self.min_range_m = params["EKF2_MIN_RNG"]
        self.no_aid_timeout_us = int(params["EKF2_NOAID_TOUT"])
        self.position_body_m = np.array([params[f"EKF2_OF_POS_{a}"] for a in "XYZ"], dtype=float)

    def reset(self) -> None:
        self.active = False
        self.last_fuse_us: int | None = None
        #: The last sample used, as EKF2 reports it; None before one.
        self.sample: FlowVelocity | None = None
        #: (time µs, bias-corrected body rates, interval s) of the recent IMU frames.
        self._gyro: deque[tuple[int, NDArray[np.float64], float]] = deque()
        self._last_known_ne = np.zeros(2)

    def add_gyro(self, time_us: int, rates_radps: NDArray[np.float64], dt_s: float) -> None:
        """One IMU frame's bias-corrected body rates over the ``dt_s`` that ended now."""
        gyro = self._gyro
        gyro.append((time_us, rates_radps.copy(), dt_s))
        while gyro and gyro[0][0] <= time_us - FLOW_MAX_WINDOW_S * 1e6:
            gyro.popleft()

    def aiding(self, time_us: int) -> bool:
        """Whether flow constrains the horizontal position: fused within EKF2_NOAID_TOUT."""
        last = self.last_fuse_us
        return self.active and last is not None and time_us - last <= self.no_aid_timeout_us

    def noise_radps(self, quality: int) -> float:
        """EKF2's ``calcOptFlowMeasVar`` (its square root): linear in the quality from
        ``EKF2_OF_N_MAX`` at ``EKF2_OF_QMIN`` to ``EKF2_OF_N_MIN`` at 255."""
        span = 255.0 - self.quality_min
        weight = min(max((quality - self.quality_min) / span, 0.0), 1.0) if span >= 1.0 else 0.0
        return self.noise_min_radps * weight + self.noise_max_radps * (1.0 - weight)

    def update(
        self,
        reading: FlowReading,
        position: PositionEstimator,
        q: NDArray[np.float64],
        height_m: float | None,
        in_air: bool,
        other_aid: bool,
        time_us: int,
    ) -> bool:
        """Take one flow sample (``height_m`` the rangefinder's height above the ground, None
        when not valid; ``other_aid`` another horizontal aid, GPS, is fused); returns whether
        it was fused. ``time_us`` is now; the sample may be older."""
        dt_s = reading.integration_timespan_us * 1e-6
        flow = np.array(reading.pixel_flow_rad, dtype=float)
        if not self.enabled or not np.isfinite(flow).all() or not 0.0 < dt_s < 1.0:
            return False  # EKF2 takes finite samples shorter than a second
        r = _quat_to_dcm(q)
        delta_angle, gyro_dt_s = self._integrate_gyro(
            reading.time_us, reading.integration_timespan_us
        )
        good = (
            reading.quality >= (self.quality_min if in_air else self.quality_min_ground)
            and math.hypot(flow[0], flow[1]) <= dt_s * self.max_rate_radps
            and r[2, 2] > self.COS_MAX_TILT
            and 0.7 * gyro_dt_s <= dt_s <= 1.3 * gyro_dt_s
        )
        if good:  # EKF2's sign is the sensor's reversed; its gyro term is -Δangle
            los = (-flow + delta_angle[:2]) / dt_s
        elif not in_air:
            los = np.zeros(2)
        else:
            return False
        if height_m is None and in_air:
            return False
        range_m = max(height_m if height_m is not None else 0.0, self.min_range_m) / r[2, 2]
        lever = np.cross(delta_angle / dt_s, self.position_body_m)  # the mount's own motion
        velocity_body = np.array([-los[1], los[0]]) * range_m - lever[:2]
        self.sample = FlowVelocity(
            reading.time_us, velocity_body, (r @ np.array([*velocity_body, 0.0]))[:2],
            -flow, los * dt_s, -delta_angle, dt_s,
        )  # fmt: skip
        noise = self.noise_radps(reading.quality)
        if not self.active:
            self._start(position, self.sample.velocity_ne_mps, range_m, noise, in_air,
                        other_aid, time_us)  # fmt: skip
            return False
        age_s = (time_us - reading.time_us) * 1e-6 + self.delay_s
        age_s += 0.5 * (self.predict_period_s + dt_s)
        if not position.fuse_flow(los, range_m, r, noise**2, age_s, self.gate_sigma, lever):
            return False
        self.last_fuse_us = time_us
        self._last_known_ne = position.position_ned_m[:2].copy()
        return True

    def _start(
        self,
        position: PositionEstimator,
        velocity_ne: NDArray[np.float64],
        range_m: float,
        noise_radps: float,
        in_air: bool,
        other_aid: bool,
        time_us: int,
    ) -> None:
        """EKF2's start of flow fusion: with no other aid, velocity to the flow's, position to
        zero on the ground or the last known in the air."""
        if not other_aid:
            start_ne = self._last_known_ne if in_air else np.zeros(2)
            position.reset_horizontal(start_ne, velocity_ne, self.RESET_POSITION_VAR_M2,
                                      (noise_radps * range_m) ** 2)  # fmt: skip
        self.active = True
        self.last_fuse_us = time_us

    def _integrate_gyro(self, end_us: int, span_us: int) -> tuple[NDArray[np.float64], float]:
        """The body rotation (rad) and the time (s) the IMU frames of ``(end - span, end]``
        cover, as ``VehicleOpticalFlow`` integrates the gyro for a chip without one."""
        delta_angle = np.zeros(3)
        covered_s = 0.0
        for time_us, rates, dt_s in self._gyro:
            if end_us - span_us < time_us <= end_us:
                delta_angle += rates * dt_s
                covered_s += dt_s
        return delta_angle, covered_s
