"""Rotation helpers the autopilot needs beyond :mod:`quad_model.frames` (whose conventions
these follow: Hamilton quaternions, scalar first, body→NED).

Written out by hand for 3-vectors because the control loop runs them thousands of times a
second: ``np.cross`` costs about 20 µs per call on 3-vectors (it reshapes for broadcasting),
this costs about 1 µs. They are also compiled into the control kernels (numba), so they use
only what numba supports.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray


@njit(cache=True)
def cross3(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cross product of two 3-vectors."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def quat_conjugate(q: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([q[0], -q[1], -q[2], -q[3]])


def yaw_quat(yaw_rad: float) -> NDArray[np.float64]:
    """Rotation by ``yaw_rad`` about the NED down axis."""
    return np.array([math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2)])


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
