"""The fast sensor path (block draws, compiled kernels) against the physics written plainly.

Each reference below states a sensor's model in straightforward numpy: one generator call
per use, in the order the models document, tones as explicit sines, rotations as
quaternion products. Given the same seed it must produce the same numbers as the fast
path; the only difference allowed is floating-point rounding from a different order of
operations (1e-12 relative on values of order 1e-3..1e5).
"""

import math

import numpy as np
import pytest

from quad_model import Environment, QuadModel
from quad_model.frames import ned_to_geodetic, quat_from_euler, quat_multiply
from quad_model.sensors import BaroModel, GpsModel, ImuModel, MagModel, NormalBlocks

ROUNDING = {"rtol": 1e-12, "atol": 1e-12}


@pytest.mark.parametrize("block_size", [1, 7, 2048])
def test_normal_blocks_hand_out_the_generator_stream_in_order(block_size):
    counts = [3, 1, 6, 0, 18, 12, 2, 5] * 20
    blocks = NormalBlocks(np.random.default_rng(5), block_size)
    taken = np.concatenate([blocks.take(count) for count in counts])
    single_draws = np.random.default_rng(5)
    expected = [single_draws.standard_normal() for _ in range(sum(counts))]
    np.testing.assert_array_equal(taken, expected)


def test_normal_blocks_cannot_be_changed_through_a_view():
    values = NormalBlocks(np.random.default_rng(5), 8).take(3)
    with pytest.raises(ValueError, match="read-only"):
        values[0] = 0.0


class ReferenceImu:
    """The IMU of :class:`ImuModel`'s docstring, one term at a time."""

    def __init__(self, vehicle, environment, rng, rate_hz):
        imu, vib = vehicle.imu, vehicle.vibration
        self.imu, self.vib, self.env, self.rng = imu, vib, environment, rng
        self.accel_std = (
            imu.accel_noise_density_mps2_per_sqrthz
            * math.sqrt(rate_hz)
            * np.asarray(imu.accel_noise_axis_gain)
        )
        self.gyro_std = (
            imu.gyro_noise_density_radps_per_sqrthz
            * math.sqrt(rate_hz)
            * np.asarray(imu.gyro_noise_axis_gain)
        )
        self.period_s = 1.0 / rate_hz
        self.gyro_bias = rng.normal(0.0, imu.gyro_turn_on_bias_std_radps, 3)
        self.accel_bias = rng.normal(0.0, imu.accel_turn_on_bias_std_mps2, 3)
        self.gyro_misalignment = rng.normal(0.0, imu.misalignment_std_rad, 3)
        self.gyro_scale = 1.0 + rng.normal(0.0, imu.gyro_scale_error_std, 3)
        self.accel_misalignment = rng.normal(0.0, imu.misalignment_std_rad, 3)
        self.accel_scale = 1.0 + rng.normal(0.0, imu.accel_scale_error_std, 3)
        harmonics_a = len(vib.accel_harmonic_amplitude_mps2)
        harmonics_g = len(vib.gyro_harmonic_amplitude_radps)
        self.accel_phase = rng.uniform(0, 2 * np.pi, (harmonics_a, 4, 3))
        self.gyro_phase = rng.uniform(0, 2 * np.pi, (harmonics_g, 4, 3))
        self.last_time_us = None

    def levels(self, speeds, tone_table, broadband_table):
        """Tone level per (rotor, axis) and broadband level per axis: (ω/ω_ref)², or the
        operating points' tables interpolated through (0, 0), ∝ ω² past the last point."""
        points = np.array(self.vib.level_rotor_speed_radps)
        if points.size == 0:
            ratio_sq = (speeds / self.vib.reference_rotor_speed_radps) ** 2
            tone = np.repeat(ratio_sq[:, None], 3, axis=1)
            return tone, np.sqrt(np.mean(tone**2, axis=0))

        def level(table):
            table = np.array(table)
            xs, last = np.concatenate(([0.0], points)), (speeds / points[-1]) ** 2
            inside = [np.interp(speeds, xs, np.concatenate(([0.0], table[:, a]))) for a in range(3)]
            beyond = last[:, None] * table[-1]
            return np.where((speeds >= points[-1])[:, None], beyond, np.array(inside).T)

        return level(tone_table), np.sqrt(np.mean(level(broadband_table) ** 2, axis=0))

    def vibration(self, truth, amplitudes, phases, broadband_std, gain, tables):
        """Σ over harmonics and rotors of A·level·sin(hθ + φ), plus broadband noise."""
        tone_level, broadband_level = self.levels(np.abs(truth.rotor_speed_radps), *tables)
        tones = np.zeros(3)
        for h, amplitude in enumerate(amplitudes, start=1):
            for r in range(4):
                for a in range(3):
                    angle = h * truth.rotor_angle_rad[r] + phases[h - 1, r, a]
                    tones[a] += amplitude * tone_level[r, a] * math.sin(angle)
        noise = broadband_std * broadband_level * self.rng.standard_normal(3)
        return (tones + noise) * gain

    @staticmethod
    def sensed(true, scale, misalignment):
        """Scale each axis, then tilt the triad by the small angles: (I + [θ]×)·diag(s)·v."""
        scaled = scale * true
        return scaled + np.cross(misalignment, scaled)

    def sample(self, truth):
        imu, vib, rng = self.imu, self.vib, self.rng
        last = self.last_time_us
        dt = self.period_s if last is None else (truth.time_us - last) / 1e6
        self.last_time_us = truth.time_us
        if dt > 0:
            gyro_walk = imu.gyro_bias_random_walk_radps2_per_sqrthz * math.sqrt(dt)
            self.gyro_bias = self.gyro_bias + gyro_walk * rng.standard_normal(3)
            accel_walk = imu.accel_bias_random_walk_mps3_per_sqrthz * math.sqrt(dt)
            self.accel_bias = self.accel_bias + accel_walk * rng.standard_normal(3)
        altitude = self.env.home.alt_amsl_m + (-truth.position_ned_m[2])
        temperature = self.env.air_temperature_degc(altitude) + imu.self_heating_k
        warming_k = temperature - imu.reference_temperature_degc
        accel_vibration = self.vibration(
            truth,
            vib.accel_harmonic_amplitude_mps2,
            self.accel_phase,
            vib.accel_broadband_std_mps2,
            vib.accel_axis_gain,
            (vib.accel_tone_level, vib.accel_broadband_level),
        )
        gyro_vibration = self.vibration(
            truth,
            vib.gyro_harmonic_amplitude_radps,
            self.gyro_phase,
            vib.gyro_broadband_std_radps,
            vib.gyro_axis_gain,
            (vib.gyro_tone_level, vib.gyro_broadband_level),
        )
        accel_true = truth.specific_force_frd_mps2 + accel_vibration
        accel = (
            self.sensed(accel_true, self.accel_scale, self.accel_misalignment)
            + self.accel_bias
            + imu.accel_bias_tempco_mps2_per_k * warming_k
            + self.accel_std * rng.standard_normal(3)
        )
        gyro_true = truth.angular_rate_frd_radps + gyro_vibration
        gyro = (
            self.sensed(gyro_true, self.gyro_scale, self.gyro_misalignment)
            + self.gyro_bias
            + imu.gyro_bias_tempco_radps_per_k * warming_k
            + self.gyro_std * rng.standard_normal(3)
        )
        return accel, gyro, temperature


def _climbing_truths(vehicle, frames, frame_s=0.001):
    """A vehicle climbing and turning on unequal rotors: speeds, angles, attitude, altitude
    and so temperature all change from sample to sample. Truth k is at k·frame_s."""
    model = QuadModel(vehicle, np.random.default_rng(3))
    command = min(1.0, 1.3 * model.hover_throttle()) * np.array([1.0, 1.03, 0.97, 1.01])
    truths = [model.truth]
    for _ in range(frames - 1):
        model.advance(command, frame_s)
        truths.append(model.truth)
    return truths


def _irregular(truths):
    """The truths with a repeated sample (no time step) and skipped frames mixed in."""
    schedule = []
    for k, truth in enumerate(truths):
        if k % 7 != 3:  # a late caller: a longer step
            schedule.append(truth)
        if k % 11 == 5:  # sampled twice: dt = 0, no bias walk
            schedule.append(truth)
    return schedule


@pytest.mark.parametrize(
    ("vehicle_name", "gyro_harmonics", "rate_hz"),
    [("f450", None, 1000.0), ("x500", None, 250.0), ("f450", (0.004,), 400.0)],
)
def test_imu_equals_reference_for_the_same_seed(
    request, variant, vehicle_name, gyro_harmonics, rate_hz
):
    vehicle = request.getfixturevalue(vehicle_name)
    if gyro_harmonics is not None:  # fewer gyro than accel tones: the kernel pads them
        vehicle = variant(vehicle, vibration={"gyro_harmonic_amplitude_radps": gyro_harmonics})
    env = Environment(temperature_offset_k=-7.0)
    fast = ImuModel(vehicle, env, np.random.default_rng(21), rate_hz)
    reference = ReferenceImu(vehicle, env, np.random.default_rng(21), rate_hz)
    schedule = _irregular(_climbing_truths(vehicle, 400))  # > 7000 draws: several blocks
    assert len({round(t.position_ned_m[2], 3) for t in schedule}) > 100  # temperature moves
    for truth in schedule:
        sample = fast.sample(truth)
        accel, gyro, temperature = reference.sample(truth)
        np.testing.assert_allclose(sample.accel_mps2, accel, **ROUNDING)
        np.testing.assert_allclose(sample.gyro_radps, gyro, **ROUNDING)
        assert sample.temperature_degc == pytest.approx(temperature, rel=1e-12)
        assert sample.time_us == truth.time_us


def test_baro_equals_reference_for_the_same_seed(f450):
    env = Environment()
    baro = f450.baro
    fast = BaroModel(f450, env, np.random.default_rng(8))
    rng = np.random.default_rng(8)
    drift_pa, last_time_us = 0.0, None
    for truth in _irregular(_climbing_truths(f450, 2500)):  # > 2048 draws
        if last_time_us is not None and truth.time_us > last_time_us:
            step = math.sqrt((truth.time_us - last_time_us) / 1e6)
            drift_pa += baro.drift_random_walk_pa_per_sqrts * step * rng.standard_normal()
        last_time_us = truth.time_us
        altitude = env.home.alt_amsl_m - truth.position_ned_m[2]
        pressure = (
            env.static_pressure_pa(altitude)
            + drift_pa
            + baro.noise_std_pa * (rng.standard_normal())
        )
        sample = fast.sample(truth)
        assert sample.pressure_pa == pytest.approx(pressure, rel=1e-12)
        assert sample.temperature_degc == env.air_temperature_degc(altitude) + baro.self_heating_k


def test_magnetometer_equals_reference_for_the_same_seed(f450):
    env = Environment()
    fast = MagModel(f450, env, np.random.default_rng(9))
    rng = np.random.default_rng(9)
    field_ned = env.magnetic_field.ned_gauss()
    attitudes = np.random.default_rng(1).uniform(-math.pi, math.pi, (800, 3))  # > 2048 draws
    model = QuadModel(f450, np.random.default_rng(1))
    for roll, pitch, yaw in attitudes:
        model.reset(attitude_quat=quat_from_euler(roll / 2, pitch / 2, yaw))
        q = model.truth.attitude_quat
        # NED → body: q* ⊗ (0, v) ⊗ q.
        conjugate = q * [1.0, -1.0, -1.0, -1.0]
        body = quat_multiply(quat_multiply(conjugate, np.r_[0.0, field_ned]), q)[1:]
        expected = (
            body + f450.mag.hard_iron_frd_gauss + f450.mag.noise_std_gauss * rng.standard_normal(3)
        )
        np.testing.assert_allclose(fast.sample(model.truth).field_gauss, expected, **ROUNDING)


def test_gps_equals_reference_for_the_same_seed(f450):
    env = Environment()
    gps = f450.gps
    fast = GpsModel(f450, env, np.random.default_rng(10))
    rng = np.random.default_rng(10)
    truths = _climbing_truths(f450, 3000)
    latency_frames = round(gps.latency_s * 1e3)
    period_frames = round(1e3 / gps.fix_rate_hz)
    std = np.array([gps.horizontal_error_std_m] * 2 + [gps.vertical_error_std_m])
    error_m = std * rng.standard_normal(3)
    decay = math.exp(-1.0 / (gps.fix_rate_hz * gps.error_correlation_time_s))
    fixes = 0
    for k, truth in enumerate(truths):
        fix = fast.sample(truth)
        if k < latency_frames or (k - latency_frames) % period_frames:
            assert fix is None
            continue
        fixes += 1
        at_epoch = truths[k - latency_frames]  # where it was at the fix's epoch
        error_m = decay * error_m + std * math.sqrt(1 - decay**2) * rng.standard_normal(3)
        velocity = at_epoch.velocity_ned_mps + gps.velocity_noise_std_mps * rng.standard_normal(3)
        home = env.home
        lat, lon, alt = ned_to_geodetic(
            at_epoch.position_ned_m + error_m, home.lat_deg, home.lon_deg, home.alt_amsl_m
        )
        assert (fix.lat_deg, fix.lon_deg) == pytest.approx((lat, lon), abs=1e-12)
        assert fix.alt_amsl_m == pytest.approx(alt, abs=1e-9)
        np.testing.assert_allclose(fix.vel_ned_mps, velocity, **ROUNDING)
    assert fixes == 29  # 10 Hz, 110 ms late: 0.11 … 2.91 s
