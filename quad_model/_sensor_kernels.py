"""The compiled per-sample physics behind :mod:`quad_model.sensors` (IMU and magnetometer).

Why compiled: one IMU sample sums 48 rotor-phase tones (2 triads × 3 axes × 4 rotors × 2
harmonics), looks 48 rotor levels up in a short table and moves a few 3-vectors. numpy
spent ~40 µs of dispatch on those tiny arrays; one numba call does the arithmetic in well
under a microsecond (``cache=True`` keeps the machine code between runs). The model keeps
the parameters and draws the normal variates; the kernel only does arithmetic, so the
random stream is decided in one place.

Why flat arrays: as in :mod:`quad_model.dynamics`, numba dispatches a few float64 arrays
far faster than a record of named ones; the layout below names every slot once.
"""

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from quad_model import frames as _frames

#: Rows of the per-triad arrays.
ACCEL = 0
GYRO = 1
TRIADS = 2

#: Rows of the per-operating-point level table ``levels[triad, kind, axis, point]``.
TONE = 0
BROADBAND = 1

# Columns of the per-triad parameter array ``triad`` (one row per triad, units of the triad).
T_NOISE_STD = 0  # 3 slots: white noise σ per sample of the sensor's x, y, z axes
T_BIAS_WALK = 3  # bias random walk density, per √s
T_TEMPCO = 4  # bias change per kelvin away from the reference temperature
T_BROADBAND_STD = 5  # broadband vibration σ at the reference rotor speed
T_AXIS_GAIN = 6  # 3 slots: vibration level of the body x, y, z axes
T_MATRIX = 9  # 9 slots: scale factor × misalignment, row-major
T_SIZE = 18

# Where each triad's variates sit in one sample's draws. The order is the model's since its
# first release, so a seed reproduces earlier runs: gyro bias walk, accel bias walk (only
# when time advanced), then accel and gyro broadband vibration, then accel and gyro white
# noise. ``_WALK_AT`` counts from the sample's first draw, the others from after the walk.
WALK_DRAWS = 6
SAMPLE_DRAWS = 12
_WALK_AT = (3, 0)  # indexed by triad: accel, gyro
_BROADBAND_AT = (0, 3)
_WHITE_AT = (6, 9)


# The convention function of quad_model.frames, compiled for the kernels (as dynamics does).
_quat_to_dcm = njit(cache=True)(_frames.quat_to_dcm)


@njit(cache=True)
def mag_sample(
    attitude_quat: NDArray[np.float64],
    field_ned_gauss: NDArray[np.float64],
    hard_iron_frd_gauss: NDArray[np.float64],
    noise_std_gauss: float,
    normals: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Earth's field rotated into the body (FRD), plus hard iron and white noise (gauss)."""
    body_field = _quat_to_dcm(attitude_quat).T @ field_ned_gauss
    return body_field + hard_iron_frd_gauss + noise_std_gauss * normals


@njit(cache=True)
def _level(speed: float, speeds: NDArray[np.float64], levels: NDArray[np.float64]) -> float:
    """The level at rotor speed ``speed`` (VibrationParams): linear between the points,
    from 0 at rest to the first, ∝ ω² beyond the last."""
    last = speeds.shape[0] - 1
    if speed >= speeds[last]:
        ratio = speed / speeds[last]
        return levels[last] * ratio * ratio
    below_speed, below_level = 0.0, 0.0
    for i in range(last + 1):
        if speed < speeds[i]:
            fraction = (speed - below_speed) / (speeds[i] - below_speed)
            return below_level + (levels[i] - below_level) * fraction
        below_speed, below_level = speeds[i], levels[i]
    return levels[last]


@njit(cache=True)
def _rotor_weights(
    rotor_speed_radps: NDArray[np.float64],
    reference_rotor_speed_radps: float,
    level_speed_radps: NDArray[np.float64],
    levels: NDArray[np.float64],
    tone_weight: NDArray[np.float64],
    broadband_scale: NDArray[np.float64],
) -> None:
    """Each rotor's tone weight ``tone_weight[t, a, r]`` and the broadband noise's scale
    ``broadband_scale[t, a]``: the RMS over the rotors of their broadband levels (independent
    sources add in power). Without operating points both follow (ω/ω_ref)²."""
    rotors = rotor_speed_radps.shape[0]
    for t in range(TRIADS):
        for a in range(3):
            power = 0.0
            for r in range(rotors):
                speed = abs(rotor_speed_radps[r])
                if level_speed_radps.shape[0] == 0:
                    ratio = speed / reference_rotor_speed_radps
                    tone = broadband = ratio * ratio
                else:
                    tone = _level(speed, level_speed_radps, levels[t, TONE, a])
                    broadband = _level(speed, level_speed_radps, levels[t, BROADBAND, a])
                tone_weight[t, a, r] = tone
                power += broadband * broadband / rotors
            broadband_scale[t, a] = math.sqrt(power)


@njit(cache=True)
def imu_sample(
    specific_force_frd_mps2: NDArray[np.float64],
    angular_rate_frd_radps: NDArray[np.float64],
    rotor_speed_radps: NDArray[np.float64],
    rotor_angle_rad: NDArray[np.float64],
    reference_rotor_speed_radps: float,
    level_speed_radps: NDArray[np.float64],
    levels: NDArray[np.float64],
    sqrt_dt_s: float,
    delta_temperature_k: float,
    triad: NDArray[np.float64],
    bias: NDArray[np.float64],
    tone_quadrature: NDArray[np.float64],
    normals: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """One accel (``out[ACCEL]``) and gyro (``out[GYRO]``) reading; updates ``bias``.

    ``level_speed_radps`` and ``levels`` are the vibration's operating points (both empty:
    the (ω/ω_ref)² law), see :func:`_rotor_weights`.

    ``sqrt_dt_s`` is 0 when time did not advance (no bias walk, ``SAMPLE_DRAWS`` normals),
    else ``normals`` holds ``WALK_DRAWS`` more in front. A tone of amplitude A at shaft
    harmonic h+1 with phase φ is A·sin((h+1)θ + φ) = A·cos φ·sin((h+1)θ) + A·sin φ·cos((h+1)θ);
    ``tone_quadrature[t, h, r, a]`` holds (A·cos φ, A·sin φ) for rotor r on axis a, so a
    sample needs one sine and cosine per rotor harmonic instead of one sine per tone.
    """
    harmonics, rotors = tone_quadrature.shape[1], tone_quadrature.shape[2]
    tone_weight = np.empty((TRIADS, 3, rotors))
    broadband_scale = np.empty((TRIADS, 3))
    _rotor_weights(
        rotor_speed_radps,
        reference_rotor_speed_radps,
        level_speed_radps,
        levels,
        tone_weight,
        broadband_scale,
    )
    sin_h = np.empty((harmonics, rotors))
    cos_h = np.empty((harmonics, rotors))
    for h in range(harmonics):
        for r in range(rotors):
            angle = (h + 1) * rotor_angle_rad[r]
            sin_h[h, r] = math.sin(angle)
            cos_h[h, r] = math.cos(angle)
    walked = sqrt_dt_s > 0.0
    drawn = WALK_DRAWS if walked else 0
    vibrating = np.empty(3)
    for t in range(TRIADS):
        row = triad[t]
        truth = specific_force_frd_mps2 if t == ACCEL else angular_rate_frd_radps
        if walked:
            walk_std = row[T_BIAS_WALK] * sqrt_dt_s
            for a in range(3):
                bias[t, a] += walk_std * normals[_WALK_AT[t] + a]
        for a in range(3):
            tones = 0.0
            for h in range(harmonics):
                for r in range(rotors):
                    in_phase = tone_quadrature[t, h, r, a, 0] * sin_h[h, r]
                    quadrature = tone_quadrature[t, h, r, a, 1] * cos_h[h, r]
                    tones += (in_phase + quadrature) * tone_weight[t, a, r]
            broadband = row[T_BROADBAND_STD] * broadband_scale[t, a]
            noise = normals[drawn + _BROADBAND_AT[t] + a]
            vibrating[a] = truth[a] + (tones + broadband * noise) * row[T_AXIS_GAIN + a]
        for i in range(3):
            sensed = 0.0
            for j in range(3):
                sensed += row[T_MATRIX + 3 * i + j] * vibrating[j]
            white = row[T_NOISE_STD + i] * normals[drawn + _WHITE_AT[t] + i]
            out[t, i] = sensed + bias[t, i] + row[T_TEMPCO] * delta_temperature_k + white
