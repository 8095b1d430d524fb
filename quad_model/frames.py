"""Frame conventions and unit conversions: the one place everyone imports them from.

Conventions (PX4's): world frame NED (north, east, down), body frame FRD (forward, right,
down). Quaternions are Hamilton, scalar first ``(w, x, y, z)``, and rotate body vectors into
NED: ``v_ned = q ⊗ v_frd ⊗ q*`` (PX4 ``matrix::Quatf`` of ``vehicle_attitude``). Euler angles
are the aerospace Z-Y-X sequence (yaw, then pitch, then roll).

The quaternion helpers are plain numpy/math code that numba also compiles: the 5 kHz kernel
in :mod:`quad_model.dynamics` and the reference autopilot's control kernels use the same
functions, so there is one definition of each convention, used by the rig too.
"""

import math

import numpy as np
from numba import njit
from numba.extending import register_jitable
from numpy.typing import ArrayLike, NDArray

#: Standard gravity (m/s²), CGPM 1901; PX4's ``CONSTANTS_ONE_G``.
STANDARD_GRAVITY_MPS2 = 9.80665
#: Earth radius used by PX4's local map projection (``CONSTANTS_RADIUS_OF_EARTH``, m).
EARTH_RADIUS_M = 6371000.0
GAUSS_PER_TESLA = 1.0e4
GAUSS_PER_NANOTESLA = 1.0e-5
#: ESC pulse range that maps to normalized throttle 0..1 (PX4 ``PWM_MAIN_MIN/MAX`` defaults).
PWM_MIN_US = 1000.0
PWM_MAX_US = 2000.0


def quat_multiply(p: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Hamilton product ``p ⊗ q`` (compose rotations: apply ``q`` first, then ``p``)."""
    pw, px, py, pz = p[0], p[1], p[2], p[3]
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    return np.array(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ]
    )


@register_jitable  # callable from Python, and from compiled kernels (and their quat_to_dcm)
def dcm_entries(w: float, x: float, y: float, z: float) -> tuple[float, ...]:
    """:func:`quat_to_dcm`'s nine entries, row by row, as plain numbers: compiled kernels
    that need them at every 5 kHz substep take them so, without allocating a matrix."""
    return (
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    )  # fmt: skip


def quat_to_dcm(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotation matrix ``R`` with ``v_ned = R @ v_frd`` for a unit quaternion body→NED."""
    return np.array(dcm_entries(q[0], q[1], q[2], q[3])).reshape(3, 3)


def body_to_ned(q: NDArray[np.float64], v_frd: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotate a body (FRD) vector into NED."""
    return quat_to_dcm(q) @ v_frd


def ned_to_body(q: NDArray[np.float64], v_ned: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotate a NED vector into the body (FRD) frame."""
    return quat_to_dcm(q).T @ v_ned


def quat_from_euler(roll_rad: float, pitch_rad: float, yaw_rad: float) -> NDArray[np.float64]:
    """Body→NED quaternion from Z-Y-X Euler angles (yaw, then pitch, then roll)."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def euler_from_quat(q: ArrayLike) -> NDArray[np.float64]:
    """Z-Y-X Euler angles ``(roll, pitch, yaw)`` in rad of a body→NED quaternion."""
    w, x, y, z = np.asarray(q, dtype=float)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    return np.array([roll, pitch, yaw_from_quat((w, x, y, z))])


def yaw_from_quat(q: ArrayLike) -> NDArray[np.float64]:
    """The Z-Y-X yaw (heading) in rad of body→NED quaternions (``w, x, y, z`` along the
    last axis), alone: a log's heading column."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def yaw_quat(yaw_rad: float) -> NDArray[np.float64]:
    """Rotation by ``yaw_rad`` about the NED down axis."""
    return np.array([math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2)])


def quat_conjugate(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """The inverse rotation of a unit quaternion."""
    return np.array([q[0], -q[1], -q[2], -q[3]])


def quat_from_dcm(r: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit quaternion (w ≥ 0) of a rotation matrix (Shepperd's method, stable everywhere)."""
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = [0.0] * 4
        q[0] = (r[k, j] - r[j, k]) / s
        q[i + 1] = 0.25 * s
        q[j + 1] = (r[j, i] + r[i, j]) / s
        q[k + 1] = (r[k, i] + r[i, k]) / s
    quat = np.array(q)
    return quat / np.linalg.norm(quat) * (1.0 if quat[0] >= 0.0 else -1.0)


def quat_between(v_from: NDArray[np.float64], v_to: NDArray[np.float64]) -> NDArray[np.float64]:
    """Shortest rotation taking unit vector ``v_from`` onto ``v_to`` (PX4 ``Quatf(v1, v2)``)."""
    dot = float(v_from @ v_to)
    if dot < -1.0 + 1e-9:  # opposite: half turn about any perpendicular axis
        axis = cross3(v_from, np.array([1.0, 0.0, 0.0]))
        if np.linalg.norm(axis) < 1e-6:
            axis = cross3(v_from, np.array([0.0, 1.0, 0.0]))
        axis = axis / np.linalg.norm(axis)
        return np.array([0.0, axis[0], axis[1], axis[2]])
    cross = cross3(v_from, v_to)
    q = np.array([1.0 + dot, cross[0], cross[1], cross[2]])
    return q / math.sqrt(float(q @ q))


@njit(cache=True)
def cross3(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cross product of two 3-vectors, written out: ``np.cross`` costs about 20 µs per call
    on 3-vectors (it reshapes for broadcasting), this about 1 µs, and numba compiles it."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def euclidean_norm(*components: float) -> float:
    """The norm of a vector given as plain floats, computed as numpy's ``linalg.norm`` (the
    root of the sum of squares; ``math.hypot`` rounds differently): the reference
    autopilot's position loop runs on floats, where numpy costs more than the arithmetic."""
    return math.sqrt(sum(c * c for c in components))


def quat_from_axis_angle(axis: ArrayLike, angle_rad: float) -> NDArray[np.float64]:
    """Quaternion of a right-handed rotation by ``angle_rad`` about ``axis``."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    s = math.sin(angle_rad / 2)
    return np.array([math.cos(angle_rad / 2), a[0] * s, a[1] * s, a[2] * s])


def ned_to_geodetic(
    position_ned_m: ArrayLike, ref_lat_deg: float, ref_lon_deg: float, ref_alt_m: float
) -> tuple[float, float, float]:
    """Latitude, longitude (deg) and altitude (m) of a local NED point.

    PX4's azimuthal equidistant projection (``MapProjection::reproject`` in
    ``src/lib/geo/geo.cpp``) so the autopilot maps the position back to the same NED point.
    """
    n, e, d = np.asarray(position_ned_m, dtype=float).tolist()  # floats: faster scalar math
    lat0, lon0 = math.radians(ref_lat_deg), math.radians(ref_lon_deg)
    x_rad, y_rad = n / EARTH_RADIUS_M, e / EARTH_RADIUS_M
    c = math.hypot(x_rad, y_rad)
    if c == 0.0:
        lat, lon = lat0, lon0
    else:
        sin_c, cos_c = math.sin(c), math.cos(c)
        lat = math.asin(cos_c * math.sin(lat0) + x_rad * sin_c * math.cos(lat0) / c)
        lon = lon0 + math.atan2(
            y_rad * sin_c, c * math.cos(lat0) * cos_c - x_rad * math.sin(lat0) * sin_c
        )
    return math.degrees(lat), math.degrees(lon), float(ref_alt_m - d)


def geodetic_to_ned(
    lat_deg: float,
    lon_deg: float,
    alt_m: float,
    ref_lat_deg: float,
    ref_lon_deg: float,
    ref_alt_m: float,
) -> NDArray[np.float64]:
    """Local NED point of a geodetic position: the inverse of :func:`ned_to_geodetic`
    (PX4 ``MapProjection::project``)."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    lat0, lon0 = math.radians(ref_lat_deg), math.radians(ref_lon_deg)
    cos_d_lon = math.cos(lon - lon0)
    arg = max(
        -1.0, min(1.0, math.sin(lat0) * math.sin(lat) + math.cos(lat0) * math.cos(lat) * cos_d_lon)
    )
    c = math.acos(arg)
    k = 1.0 if c == 0.0 else c / math.sin(c)
    north = k * (math.cos(lat0) * math.sin(lat) - math.sin(lat0) * math.cos(lat) * cos_d_lon)
    east = k * math.cos(lat) * math.sin(lon - lon0)
    return np.array([north * EARTH_RADIUS_M, east * EARTH_RADIUS_M, ref_alt_m - alt_m])


def pwm_to_throttle(pwm_us: ArrayLike) -> NDArray[np.float64]:
    """Normalized ESC throttle 0..1 from a pulse width in µs (clamped to the PWM range)."""
    pwm = np.asarray(pwm_us, dtype=float)
    # minimum(maximum()) is np.clip's result at two thirds of its call cost (every rig frame).
    return np.minimum(np.maximum((pwm - PWM_MIN_US) / (PWM_MAX_US - PWM_MIN_US), 0.0), 1.0)
