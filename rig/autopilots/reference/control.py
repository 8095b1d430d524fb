"""PX4's multicopter control cascade, one class per PX4 module.

position P → velocity PID → acceleration → thrust vector and attitude (``mc_pos_control``
``PositionControl``) → quaternion attitude P (``mc_att_control`` ``AttitudeControl``) →
body-rate PID with the D term on the filtered measurement (``mc_rate_control``
``RateControl``) → control allocation of any multirotor geometry with sequential
desaturation (``control_allocator``). The algorithms follow PX4's (files named on each
class); gains are PX4's parameters, read in ``configure`` so a parameter change takes effect
at the next frame.

Conventions are PX4's: NED world, FRD body, quaternions body→NED scalar first, thrust as a
normalized vector whose NED-z is negative for lift, torque normalized to -1..1.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from quad_model import frames
from quad_model.frames import STANDARD_GRAVITY_MPS2, cross3, euclidean_norm, quat_from_dcm
from rig.autopilots.reference.params import Parameters

# The per-frame parts of the cascade (gyro filters, attitude and rate control, allocation) are
# compiled with numba: each is a few dozen operations on 3- and 4-vectors, which numpy runs at
# ~1 µs per operation and compiled code at ~1 ns, and together they ran every IMU frame. The
# position loop runs at 50 Hz on plain floats (``_Vector``). The same convention helpers:
_quat_to_dcm = njit(cache=True)(frames.quat_to_dcm)
_quat_multiply = njit(cache=True)(frames.quat_multiply)
_quat_conjugate = njit(cache=True)(frames.quat_conjugate)
_quat_between = njit(cache=True)(frames.quat_between)

_AXES = ("ROLL", "PITCH", "YAW")
_INT_LIMITS = ("MC_RR_INT_LIM", "MC_PR_INT_LIM", "MC_YR_INT_LIM")
#: PX4 RateControl: the I gain fades with the rate error, reaching 0 at 400 °/s.
_I_FADE_RATE_RADPS = math.radians(400.0)


class LowPass2p:
    """Second-order Butterworth low-pass on a 3-vector, PX4's ``LowPassFilter2p``.

    Designed by :func:`butterworth2` and run by hand one sample at a time (transposed
    direct form II), because ``lfilter`` per 3-sample call costs more than the whole loop.
    A cutoff of 0 or at/above Nyquist passes the signal through, as in PX4.
    """

    def __init__(self, sample_rate_hz: float, cutoff_hz: float) -> None:
        self.enabled = 0.0 < cutoff_hz < 0.5 * sample_rate_hz
        if self.enabled:
            self.b, self.a = butterworth2(cutoff_hz, sample_rate_hz)
        self._state = np.zeros((2, 3))  # z1, z2
        self._started = False

    def reset(self, value: NDArray[np.float64]) -> NDArray[np.float64]:
        """Start at steady state on ``value`` (no start-up transient)."""
        if self.enabled:
            b, a = self.b, self.a
            self._state[1] = (b[2] - a[2]) * value
            self._state[0] = (b[1] - a[1]) * value + self._state[1]
            self._started = True
        return value

    def apply(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        if not self.enabled:
            return x
        if not self._started:
            return self.reset(x)
        return _lowpass_step(self.b, self.a, self._state, np.asarray(x, dtype=float))


def butterworth2(
    cutoff_hz: float, sample_rate_hz: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(b, a)`` of the digital second-order Butterworth low-pass: the analogue prototype
    through the bilinear transform, prewarped so the -3 dB point lands on ``cutoff_hz``.

    What ``scipy.signal.butter(2, cutoff_hz, fs=sample_rate_hz)`` returns (a test compares
    them), in closed form because importing ``scipy.signal`` costs about a second at every
    autopilot start, for one design of three coefficients.
    """
    w = math.tan(math.pi * cutoff_hz / sample_rate_hz)  # the prewarped analogue cutoff
    w2, damping = w * w, math.sqrt(2.0) * w
    norm = 1.0 + damping + w2
    b0 = w2 / norm
    b = np.array([b0, 2.0 * b0, b0])
    a = np.array([1.0, 2.0 * (w2 - 1.0) / norm, (1.0 - damping + w2) / norm])
    return b, a


@njit(cache=True)
def _lowpass_step(b: np.ndarray, a: np.ndarray, state: np.ndarray, x: np.ndarray) -> np.ndarray:
    y = b[0] * x + state[0]
    state[0] = b[1] * x - a[1] * y + state[1]
    state[1] = b[2] * x - a[2] * y
    return y


#: PX4 ``VehicleAngularVelocity::CheckFilters``: the gyro filters are redesigned when the
#: measured IMU rate differs from their design rate by more than 1 %.
_RATE_TOLERANCE = 0.01
#: Sample intervals averaged per rate check. PX4 averages 1000; 100 corrects a wrong design
#: within 0.4 s at 250 Hz and still averages a jittery link's intervals.
_RATE_WINDOW_SAMPLES = 100
#: PX4 bounds the derivative's dt to 0.2..20 ms (``VehicleAngularVelocity::Run``).
_DT_RANGE_S = (2e-4, 0.02)


class AngularVelocityFilter:
    """Filtered body rates and angular acceleration, PX4's ``VehicleAngularVelocity``:
    gyro low-pass ``IMU_GYRO_CUTOFF``; derivative of the raw rate low-passed at
    ``IMU_DGYRO_CUTOFF`` for the rate controller's D term.

    The digital filters are designed for the IMU rate measured from the sample timestamps,
    never assumed: a 40 Hz Butterworth designed for 1 kHz but run at 250 Hz cuts at 10 Hz,
    and its phase lag drives the rate loop into a limit cycle. The first interval sets the
    design; each window of intervals re-checks it, as PX4 does, within 1 %.
    """

    def __init__(self, params: Parameters) -> None:
        self.sample_rate_hz: float | None = None  # None: no interval seen yet
        self.rates_radps = np.zeros(3)
        self.angular_accel_radps2 = np.zeros(3)
        self._last_time_us: int | None = None
        self._previous = np.zeros(3)
        self._interval_sum_us = 0
        self._interval_count = 0
        self.configure(params)

    def configure(self, params: Parameters) -> None:
        """Take the cutoffs; the filters restart at the current outputs (no transient)."""
        self.gyro_cutoff_hz = params["IMU_GYRO_CUTOFF"]
        self.dgyro_cutoff_hz = params["IMU_DGYRO_CUTOFF"]
        if self.sample_rate_hz is not None:
            self._design(self.sample_rate_hz)

    def update(self, rates_radps: NDArray[np.float64], time_us: int) -> None:
        """One gyro sample (bias-corrected, rad/s) taken at ``time_us``."""
        last, self._last_time_us = self._last_time_us, time_us
        rates_radps = np.asarray(rates_radps, dtype=float)
        if last is None or time_us <= last:  # no interval: nothing to differentiate
            self._previous = self.rates_radps = rates_radps
            self._interval_sum_us = self._interval_count = 0
            return
        interval_us = time_us - last
        self._check_rate(interval_us)
        dt_s = min(max(interval_us * 1e-6, _DT_RANGE_S[0]), _DT_RANGE_S[1])
        derivative = (rates_radps - self._previous) / dt_s
        self._previous = rates_radps
        self.rates_radps = self._rate_filter.apply(rates_radps)
        self.angular_accel_radps2 = self._accel_filter.apply(derivative)

    def _check_rate(self, interval_us: int) -> None:
        if not _DT_RANGE_S[0] <= interval_us * 1e-6 <= _DT_RANGE_S[1]:
            self._interval_sum_us = self._interval_count = 0  # a gap is not a rate
            return
        if self.sample_rate_hz is None:
            self._design(1e6 / interval_us)
            return
        self._interval_sum_us += interval_us
        self._interval_count += 1
        if self._interval_count < _RATE_WINDOW_SAMPLES:
            return
        measured_hz = 1e6 * self._interval_count / self._interval_sum_us
        self._interval_sum_us = self._interval_count = 0
        if abs(measured_hz - self.sample_rate_hz) > _RATE_TOLERANCE * self.sample_rate_hz:
            self._design(measured_hz)

    def _design(self, sample_rate_hz: float) -> None:
        self.sample_rate_hz = sample_rate_hz
        self._rate_filter = LowPass2p(sample_rate_hz, self.gyro_cutoff_hz)
        self._rate_filter.reset(self.rates_radps)
        self._accel_filter = LowPass2p(sample_rate_hz, self.dgyro_cutoff_hz)
        self._accel_filter.reset(self.angular_accel_radps2)


class RateController:
    """Body-rate PID with feed-forward, PX4 ``src/lib/rate_control/rate_control.cpp``.

    ``torque = K·(P·e + I∫e − D·α) + FF·ω_sp`` with ``α`` the filtered angular acceleration
    (D on the measurement, so set-point steps do not kick), the integral frozen on the
    ground and in the saturated direction, faded for large errors, and clamped to
    ``MC_*_INT_LIM``. The yaw torque then goes through PX4's first-order low-pass at
    ``MC_YAW_TQ_CUTOFF`` (``MulticopterRateControl``, v1.15 on): yaw acts through the
    rotors' speed differences, and at high frequency their spin-up reaction torque
    (J_rotor·dω/dt) outweighs the drag torque, so an unfiltered yaw loop keeps enough gain to
    limit-cycle (at 25 Hz on the F450 with the IMU at 250 Hz).
    """

    def __init__(self, params: Parameters) -> None:
        self.integral = np.zeros(3)
        self.yaw_torque = 0.0
        self.saturated_positive = np.zeros(3, dtype=bool)
        self.saturated_negative = np.zeros(3, dtype=bool)
        self.configure(params)

    def configure(self, params: Parameters) -> None:
        k = np.array([params[f"MC_{a}RATE_K"] for a in _AXES])
        self.gain_p = k * [params[f"MC_{a}RATE_P"] for a in _AXES]
        self.gain_i = k * [params[f"MC_{a}RATE_I"] for a in _AXES]
        self.gain_d = k * [params[f"MC_{a}RATE_D"] for a in _AXES]
        self.gain_ff = np.array([params[f"MC_{a}RATE_FF"] for a in _AXES])
        self.integral_limit = np.array([params[n] for n in _INT_LIMITS])
        cutoff_hz = params["MC_YAW_TQ_CUTOFF"]
        self.yaw_time_constant_s = 1.0 / (2.0 * math.pi * cutoff_hz) if cutoff_hz > 0 else 0.0
        self._gains = np.stack((self.gain_p, self.gain_i, self.gain_d, self.gain_ff,
                                self.integral_limit))  # fmt: skip

    def reset_integral(self) -> None:
        """Clear the integral and the yaw filter's memory (the loop restarts)."""
        self.integral[:] = 0.0
        self.yaw_torque = 0.0

    def update(
        self,
        rates_radps: NDArray[np.float64],
        rates_sp_radps: NDArray[np.float64],
        angular_accel_radps2: NDArray[np.float64],
        dt_s: float,
        landed: bool,
    ) -> NDArray[np.float64]:
        torque = _rate_step(
            self._gains, self.integral, rates_radps, rates_sp_radps, angular_accel_radps2, dt_s,
            landed, self.saturated_positive, self.saturated_negative,
        )  # fmt: skip
        # PX4's AlphaFilter: α = dt / (dt + τ), so a cutoff of 0 (τ = 0) passes the torque.
        alpha = dt_s / (dt_s + self.yaw_time_constant_s)
        self.yaw_torque += alpha * (torque[2] - self.yaw_torque)
        torque[2] = self.yaw_torque
        return torque


@njit(cache=True)
def _rate_step(
    gains: np.ndarray,
    integral: np.ndarray,
    rates: np.ndarray,
    rates_sp: np.ndarray,
    angular_accel: np.ndarray,
    dt: float,
    landed: bool,
    sat_pos: np.ndarray,
    sat_neg: np.ndarray,
) -> np.ndarray:
    """Torque of :class:`RateController`; the integral is updated in place."""
    torque = np.empty(3)
    for i in range(3):
        error = rates_sp[i] - rates[i]
        torque[i] = (
            gains[0, i] * error + integral[i] - gains[2, i] * angular_accel[i]
            + gains[3, i] * rates_sp[i]
        )  # fmt: skip
        if landed:
            continue
        if sat_pos[i]:
            error = min(error, 0.0)
        if sat_neg[i]:
            error = max(error, 0.0)
        fade = max(0.0, 1.0 - (error / _I_FADE_RATE_RADPS) ** 2)
        limit = gains[4, i]
        integral[i] = min(max(integral[i] + fade * gains[1, i] * error * dt, -limit), limit)
    return torque


class AttitudeController:
    """Quaternion attitude P, PX4 ``mc_att_control/AttitudeControl/AttitudeControl.cpp``.

    Tilt is corrected first through the reduced attitude; the remaining yaw error is
    weighted by ``MC_YAW_WEIGHT`` (and the yaw gain compensated for it), then rates are
    ``2·sign(qe_w)·qe_xyz·P`` limited to ``MC_*RATE_MAX``.
    """

    def __init__(self, params: Parameters) -> None:
        self.configure(params)

    def configure(self, params: Parameters) -> None:
        self.yaw_weight = min(max(params["MC_YAW_WEIGHT"], 0.0), 1.0)
        gain = np.array([params["MC_ROLL_P"], params["MC_PITCH_P"], params["MC_YAW_P"]])
        if self.yaw_weight > 1e-4:
            gain[2] /= self.yaw_weight
        self.gain = gain
        self.rate_limit_radps = np.radians(
            [params["MC_ROLLRATE_MAX"], params["MC_PITCHRATE_MAX"], params["MC_YAWRATE_MAX"]]
        )

    def update(
        self, q: NDArray[np.float64], q_sp: NDArray[np.float64], yawspeed_sp_radps: float = 0.0
    ) -> NDArray[np.float64]:
        return _attitude_rates(
            np.asarray(q, dtype=float), np.asarray(q_sp, dtype=float), yawspeed_sp_radps,
            self.yaw_weight, self.gain, self.rate_limit_radps,
        )  # fmt: skip


@njit(cache=True)
def _attitude_rates(
    q: np.ndarray,
    q_sp: np.ndarray,
    yawspeed_sp: float,
    yaw_weight: float,
    gain: np.ndarray,
    rate_limit: np.ndarray,
) -> np.ndarray:
    """Body-rate set-point of :class:`AttitudeController`."""
    e_z = _quat_to_dcm(q)[:, 2].copy()
    e_z_sp = _quat_to_dcm(q_sp)[:, 2].copy()
    q_reduced = _quat_between(e_z, e_z_sp)
    if abs(q_reduced[1]) > 1 - 1e-5 or abs(q_reduced[2]) > 1 - 1e-5:
        q_reduced = q_sp  # thrust exactly opposite: full attitude control
    else:
        q_reduced = _quat_multiply(q_reduced, q)
    q_yaw = _quat_multiply(_quat_conjugate(q_reduced), q_sp)
    if q_yaw[0] < 0.0:
        q_yaw = -q_yaw
    q_mix = np.array(
        [
            math.cos(yaw_weight * math.acos(min(max(q_yaw[0], -1.0), 1.0))),
            0.0,
            0.0,
            math.sin(yaw_weight * math.asin(min(max(q_yaw[3], -1.0), 1.0))),
        ]
    )
    q_target = _quat_multiply(q_reduced, q_mix)
    q_error = _quat_multiply(_quat_conjugate(q), q_target)
    sign = 1.0 if q_error[0] >= 0.0 else -1.0
    rates_sp = 2.0 * sign * q_error[1:] * gain
    # the commanded yaw rate is fed forward about the world down axis, seen in the body
    rates_sp += _quat_to_dcm(q)[2] * yawspeed_sp
    return np.minimum(np.maximum(rates_sp, -rate_limit), rate_limit)


def limit_tilt(body_z: _Vector, max_tilt_rad: float) -> _Vector:
    """Bring the body z axis (unit, in NED; level is ``(0, 0, 1)``) back into a cone of
    ``max_tilt_rad`` about the world z axis (PX4 ``ControlMath::limitTilt``)."""
    x, y, z = body_z
    dot = min(max(z, -1.0), 1.0)  # body z · world z
    if math.acos(dot) <= max_tilt_rad:
        return body_z
    rejection = (x, y, z - dot)  # body z less its part along world z
    norm = euclidean_norm(*rejection)
    rx, ry, rz = (r / norm for r in rejection) if norm > 1e-9 else (1.0, 0.0, 0.0)
    sine = math.sin(max_tilt_rad)
    return sine * rx, sine * ry, math.cos(max_tilt_rad) + sine * rz


def constrain_xy(
    v0: tuple[float, float], v1: tuple[float, float], max_norm: float
) -> tuple[float, float]:
    """``v0 + s·v1`` with the largest ``s ≤ 1`` whose norm fits ``max_norm``, keeping ``v0``
    first (PX4 ``ControlMath::constrainXY``: the position term wins over feed-forward)."""
    (x0, y0), (x1, y1) = v0, v1
    if euclidean_norm(x0 + x1, y0 + y1) <= max_norm:
        return x0 + x1, y0 + y1
    n0 = euclidean_norm(x0, y0)
    if n0 >= max_norm:
        return x0 / n0 * max_norm, y0 / n0 * max_norm
    # |v0 + s v1| = max_norm, s in [0, 1]: a quadratic in s
    a, b, c = x1 * x1 + y1 * y1, 2.0 * (x0 * x1 + y0 * y1), n0**2 - max_norm**2
    s = (-b + math.sqrt(b * b - 4 * a * c)) / (2 * a)
    return x0 + s * x1, y0 + s * y1


def _finite(value: float) -> float:
    """``np.nan_to_num`` of one float: NaN (not controlled) is 0, an infinity the largest
    float of its sign."""
    if math.isnan(value):
        return 0.0
    return min(max(value, -_FLOAT_MAX), _FLOAT_MAX)


_FLOAT_MAX = float(np.finfo(np.float64).max)
#: A 3-vector of the position loop: plain floats (numpy's per-operation cost was most of
#: the 50 Hz loop's time, and the autopilot's answer waits for it).
_Vector = tuple[float, float, float]


def thrust_to_attitude(
    thrust_ned: NDArray[np.float64], yaw_rad: float
) -> tuple[NDArray[np.float64], float]:
    """Attitude whose body z is against the thrust vector, with the requested heading, and the
    collective thrust (PX4 ``ControlMath::bodyzToAttitude``)."""
    thrust = np.asarray(thrust_ned, dtype=float)
    magnitude = euclidean_norm(*thrust.tolist())
    body_z = -thrust / magnitude if magnitude > 1e-9 else np.array([0.0, 0.0, 1.0])
    body_x = cross3(np.array([-math.sin(yaw_rad), math.cos(yaw_rad), 0.0]), body_z)
    if body_z[2] < 0.0:
        body_x = -body_x
    if abs(body_z[2]) < 1e-6:  # thrust horizontal: keep the nose along the heading
        body_x = np.array([0.0, 0.0, 1.0])
    body_x = body_x / euclidean_norm(*body_x.tolist())
    body_y = cross3(body_z, body_x)
    # the rotation's columns are the body axes in NED
    return quat_from_dcm(np.column_stack((body_x, body_y, body_z))), magnitude


class FilteredDerivative:
    """PX4's ``BlockDerivative``: the difference quotient through a first-order low-pass.

    The low-pass is PX4's ``BlockLowPass`` (``a = b / (1 + b)``, ``b = 2π·f_c·dt``; a
    cutoff of 0 disables it, as ``MPC_VELD_LP = 0`` does). The first update after a reset
    returns 0, since one sample has no derivative.
    """

    def __init__(self, cutoff_hz: float) -> None:
        self.cutoff_hz = cutoff_hz
        self.reset()

    def reset(self) -> None:
        self._previous: NDArray[np.float64] | None = None
        self.value = np.zeros(3)

    def update(self, sample: NDArray[np.float64], dt_s: float) -> NDArray[np.float64]:
        previous, self._previous = self._previous, np.array(sample, dtype=float)
        if previous is None or dt_s <= 0.0:
            return self.value
        raw = (self._previous - previous) / dt_s
        if self.cutoff_hz > 0.0:
            b = 2.0 * math.pi * self.cutoff_hz * dt_s
            self.value = self.value + (b / (1.0 + b)) * (raw - self.value)
        else:
            self.value = raw
        return self.value


class PositionController:
    """PX4 ``mc_pos_control/PositionControl/PositionControl.cpp``.

    Position P → velocity set-point (horizontal limit, position term first); velocity PID
    (D on the velocity estimate's derivative, low-passed at ``MPC_VELD_LP`` as PX4's
    ``_vel_*_deriv``: the raw accelerometer would feed frame vibration straight into the
    tilt set-point) plus the trajectory's acceleration as feed-forward → acceleration
    set-point; acceleration → thrust vector
    through the hover thrust, tilt limited to ``MPC_TILTMAX_AIR``; vertical thrust has
    priority with a horizontal margin ``MPC_THR_XY_MARG``; anti-windup vertical by clamping
    and horizontal by tracking. Set-point entries that are NaN are not controlled.
    """

    def __init__(self, params: Parameters) -> None:
        self.velocity_integral = np.zeros(3)
        self.velocity_derivative = FilteredDerivative(params["MPC_VELD_LP"])
        self.configure(params)

    def configure(self, params: Parameters) -> None:
        self.gain_pos = (params["MPC_XY_P"], params["MPC_XY_P"], params["MPC_Z_P"])
        xy_p, z_p = params["MPC_XY_VEL_P_ACC"], params["MPC_Z_VEL_P_ACC"]
        xy_i, z_i = params["MPC_XY_VEL_I_ACC"], params["MPC_Z_VEL_I_ACC"]
        xy_d, z_d = params["MPC_XY_VEL_D_ACC"], params["MPC_Z_VEL_D_ACC"]
        self.gain_vel_p = (xy_p, xy_p, z_p)
        self.gain_vel_i = (xy_i, xy_i, z_i)
        self.gain_vel_d = (xy_d, xy_d, z_d)
        self.hover_thrust = params["MPC_THR_HOVER"]
        self.thrust_min = max(params["MPC_THR_MIN"], 10e-4)
        self.thrust_max = params["MPC_THR_MAX"]
        self.thrust_xy_margin = params["MPC_THR_XY_MARG"]
        self.tilt_max_rad = math.radians(params["MPC_TILTMAX_AIR"])
        self.velocity_derivative.cutoff_hz = params["MPC_VELD_LP"]

    def reset_integral(self) -> None:
        """Clear the velocity integral and the derivative's memory (the loop restarts)."""
        self.velocity_integral[:] = 0.0
        self.velocity_derivative.reset()

    def update(
        self,
        position_ned_m: NDArray[np.float64],
        velocity_ned_mps: NDArray[np.float64],
        position_sp: NDArray[np.float64],
        velocity_sp: NDArray[np.float64],
        velocity_limits_mps: tuple[float, float, float],
        dt_s: float,
        freeze_integral: bool = False,
        acceleration_sp: NDArray[np.float64] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """One step → ``(thrust_ned, velocity_sp_used, acceleration_sp)``.

        ``velocity_limits_mps`` is (horizontal, up, down); ``acceleration_sp`` the
        feed-forward (PX4 adds the PID's output to the trajectory's acceleration).
        """
        position = np.asarray(position_ned_m, dtype=float).tolist()
        velocity = np.asarray(velocity_ned_mps, dtype=float).tolist()
        position_wanted = np.asarray(position_sp, dtype=float).tolist()
        velocity_wanted = np.asarray(velocity_sp, dtype=float).tolist()
        vel_from_pos = [
            _finite((wanted - p) * gain)
            for wanted, p, gain in zip(position_wanted, position, self.gain_pos, strict=True)
        ]
        feed_forward = [_finite(v) for v in velocity_wanted]
        horizontal, up, down = velocity_limits_mps
        vel_sp = (
            *constrain_xy((vel_from_pos[0], vel_from_pos[1]), (feed_forward[0], feed_forward[1]),
                          horizontal),
            # the up limit wins, as in PX4's constrain: during a take-off ramp it is negative
            max(min(vel_from_pos[2] + feed_forward[2], down), -up),
        )  # fmt: skip
        accel_ned_mps2 = self.velocity_derivative.update(velocity_ned_mps, dt_s).tolist()
        feed_forward_acc = (0.0, 0.0, 0.0) if acceleration_sp is None else [
            _finite(a) for a in np.asarray(acceleration_sp, dtype=float).tolist()]  # fmt: skip
        vel_error = [0.0, 0.0, 0.0]
        acc_sp = [0.0, 0.0, 0.0]
        integral = self.velocity_integral.tolist()
        for i in range(3):
            # an axis with neither a position nor a velocity set-point is not controlled:
            # zero acceleration (level flight for x/y), as PX4 does for NaN set-points
            if math.isnan(position_wanted[i]) and math.isnan(velocity_wanted[i]):
                acc_sp[i] = feed_forward_acc[i]
                continue
            vel_error[i] = vel_sp[i] - velocity[i]
            damping = accel_ned_mps2[i] * self.gain_vel_d[i]
            acc_sp[i] = vel_error[i] * self.gain_vel_p[i] + integral[i] - damping
            acc_sp[i] += feed_forward_acc[i]
        tx, ty, tz = self._acceleration_to_thrust(acc_sp)

        if (tz >= -self.thrust_min and vel_error[2] >= 0.0) or (
            tz <= -self.thrust_max and vel_error[2] <= 0.0
        ):
            vel_error[2] = 0.0  # vertical anti-windup: stop integrating into a limit
        xy_norm = euclidean_norm(tx, ty)
        allocated_xy = min(xy_norm, self.thrust_xy_margin)
        tz = max(tz, -math.sqrt(self.thrust_max**2 - allocated_xy**2))
        xy_max = math.sqrt(max(self.thrust_max**2 - tz**2, 0.0))
        if xy_norm > xy_max:
            tx, ty = tx * (xy_max / xy_norm), ty * (xy_max / xy_norm)
        # horizontal tracking anti-windup (Rundqwist 1990), as PX4
        produced = STANDARD_GRAVITY_MPS2 / self.hover_thrust
        ax, ay = tx * produced, ty * produced
        if acc_sp[0] * acc_sp[0] + acc_sp[1] * acc_sp[1] <= ax * ax + ay * ay:
            ax, ay = acc_sp[0], acc_sp[1]
        tracking = 2.0 / self.gain_vel_p[0]
        vel_error[0] -= tracking * (acc_sp[0] - ax)
        vel_error[1] -= tracking * (acc_sp[1] - ay)
        if not freeze_integral:
            self.velocity_integral += np.multiply(vel_error, self.gain_vel_i) * dt_s
            z = self.velocity_integral[2]
            self.velocity_integral[2] = math.copysign(min(abs(z), STANDARD_GRAVITY_MPS2), z)
        return np.array([tx, ty, tz]), np.array(vel_sp), np.array(acc_sp)

    def _acceleration_to_thrust(self, acc_sp: list[float]) -> _Vector:
        ax, ay, az = acc_sp
        norm = euclidean_norm(-ax, -ay, STANDARD_GRAVITY_MPS2)
        body_z = limit_tilt((-ax / norm, -ay / norm, STANDARD_GRAVITY_MPS2 / norm),
                            self.tilt_max_rad)  # fmt: skip
        collective = az * (self.hover_thrust / STANDARD_GRAVITY_MPS2) - self.hover_thrust
        collective = min(collective / body_z[2], -self.thrust_min)
        return body_z[0] * collective, body_z[1] * collective, body_z[2] * collective


#: PX4 ``FLT_EPSILON``: below it a scale or thrust coefficient counts as zero.
_FLT_EPSILON = float(np.finfo(np.float32).eps)
#: PX4 ``ControlAllocationSequentialDesaturation::MINIMUM_YAW_MARGIN``: yaw may push the
#: outputs this far above full before it gives way.
_YAW_MARGIN = 0.15
#: PX4 ``computeDesaturationGain``: an output weaker than this along a direction is left
#: out of the gain (it would ask for a large one).
_WEAK_OUTPUT = 0.2


class ControlAllocator:
    """Multirotor allocation from the rotor geometry ``CA_ROTOR_COUNT`` and
    ``CA_ROTORi_PX/PY/PZ/CT/KM``, as PX4's ``control_allocator`` with ``MC_AIRMODE`` 0.

    The effectiveness of rotor ``i`` at ``r`` with thrust axis ``a = -z`` is moment
    ``CT·(r × a − KM·a)`` and thrust ``CT·a`` (PX4 ``ActuatorEffectivenessRotors``; a rotor
    without thrust coefficient is left out). Rows here are roll, pitch and yaw torque and
    the collective thrust ``-Fz`` (PX4's x and y thrust rows are zero for upward rotors,
    and its z row is this one's negative). The pseudo-inverse is normalized as PX4's
    ``ControlAllocationPseudoInverse`` does (:func:`allocation_scale`), so the rate gains
    mean what they mean in PX4 whatever the rotor count. Outputs are desaturated as PX4's
    ``ControlAllocationSequentialDesaturation``: thrust (down only), roll, pitch, then yaw
    added with 15 % headroom above full and thrust lowered again; then clipped to 0..1.
    """

    def __init__(self, params: Parameters) -> None:
        self.configure(params)
        self.unallocated = np.zeros(4)

    def configure(self, params: Parameters) -> None:
        count = int(params["CA_ROTOR_COUNT"])
        effectiveness = np.zeros((4, count))  # rows: roll, pitch, yaw torque; collective thrust
        axis = np.array([0.0, 0.0, -1.0])
        for i in range(count):
            ct, km = params[f"CA_ROTOR{i}_CT"], params[f"CA_ROTOR{i}_KM"]
            if abs(ct) < _FLT_EPSILON:
                continue
            position = np.array([params[f"CA_ROTOR{i}_P{a}"] for a in "XYZ"])
            effectiveness[:3, i] = ct * (cross3(position, axis) - km * axis)
            effectiveness[3, i] = ct
        mix = np.linalg.pinv(effectiveness)
        scale = allocation_scale(mix)
        mix /= scale
        mix[np.abs(mix) < 1e-3] = 0.0
        self.motor_count = count
        self.mix = mix
        self._mix_columns = np.ascontiguousarray(mix.T)  # roll, pitch, yaw, thrust directions
        #: What the outputs achieve, in the normalized units (PX4 ``getAllocatedControl``).
        self.effectiveness = effectiveness * scale[:, None]

    def allocate(
        self, torque: NDArray[np.float64], collective_thrust: float
    ) -> NDArray[np.float64]:
        """Motor commands 0..1 for a normalized torque (3) and collective thrust (0..1).

        ``unallocated`` keeps set-point minus achieved (roll, pitch, yaw, thrust) for the
        rate controller's anti-windup.
        """
        outputs, self.unallocated = _allocate(
            self._mix_columns,
            self.effectiveness,
            np.asarray(torque, dtype=float),
            collective_thrust,
        )
        return outputs


def allocation_scale(mix: NDArray[np.floating]) -> NDArray[np.float64]:
    """PX4 ``updateControlAllocationMatrixScale`` for a pseudo-inverse (rotors × roll,
    pitch, yaw, thrust): roll and pitch share the larger of their RMS entry over half the
    rotors that take part, yaw its largest entry, thrust its mean over the rotors that
    take part. A scale PX4 would not divide by (zero) is 1."""

    def roll_pitch(column: NDArray[np.floating]) -> float:
        taking_part = np.count_nonzero(np.abs(column) > 1e-3)
        return math.sqrt(column @ column / (taking_part / 2.0)) if taking_part else 1.0

    thrust = np.abs(mix[:, 3])
    taking_part = np.count_nonzero(thrust > _FLT_EPSILON)
    rp = max(roll_pitch(mix[:, 0]), roll_pitch(mix[:, 1]))
    scale = np.array([rp, rp, mix[:, 2].max(), thrust.sum() / taking_part if taking_part else 1.0])
    return np.where(scale > _FLT_EPSILON, scale, 1.0)


@njit(cache=True)
def _allocate(
    mix_columns: np.ndarray, effectiveness: np.ndarray, torque: np.ndarray, collective_thrust: float
) -> tuple[np.ndarray, np.ndarray]:
    """Outputs and unallocated set-point of :meth:`ControlAllocator.allocate`."""
    roll, pitch, yaw, thrust = mix_columns[0], mix_columns[1], mix_columns[2], mix_columns[3]
    outputs = roll * torque[0] + pitch * torque[1] + thrust * collective_thrust
    outputs = _desaturate(outputs, thrust, True, 1.0)
    outputs = _desaturate(outputs, roll, False, 1.0)
    outputs = _desaturate(outputs, pitch, False, 1.0)
    outputs = outputs + yaw * torque[2]
    outputs = _desaturate(outputs, yaw, False, 1.0 + _YAW_MARGIN)
    outputs = _desaturate(outputs, thrust, True, 1.0)
    outputs = np.minimum(np.maximum(outputs, 0.0), 1.0)
    wanted = np.array([torque[0], torque[1], torque[2], collective_thrust])
    return outputs, wanted - effectiveness @ outputs


@njit(cache=True)
def _desaturation_gain(
    outputs: np.ndarray, direction: np.ndarray, lower: float, upper: float
) -> float:
    """PX4 ``computeDesaturationGain``: how far along ``direction`` to move to fit the range."""
    k_min = k_max = 0.0
    for i in range(outputs.shape[0]):
        d, value = direction[i], outputs[i]
        if abs(d) < _WEAK_OUTPUT:
            continue
        if value < lower:
            k = (lower - value) / d
        elif value > upper:
            k = (upper - value) / d
        else:
            continue
        k_min, k_max = min(k_min, k), max(k_max, k)
    return k_min + k_max


@njit(cache=True)
def _desaturate(
    outputs: np.ndarray, direction: np.ndarray, reduce_only: bool, upper: float
) -> np.ndarray:
    """PX4 ``desaturateActuators``: move ``outputs`` along ``direction`` into ``0..upper``,
    a full step then half a step (to centre a range that cannot fit); ``reduce_only``
    skips both when the full step would raise the outputs (PX4 checks only that one)."""
    gain = _desaturation_gain(outputs, direction, 0.0, upper)
    if reduce_only and gain > 0.0:
        return outputs
    outputs = outputs + gain * direction
    return outputs + 0.5 * _desaturation_gain(outputs, direction, 0.0, upper) * direction
