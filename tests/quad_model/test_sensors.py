"""Sensor physics: noise levels from datasheet densities, vibration, bias, fields, GPS timing."""

import math
from fractions import Fraction

import numpy as np
import pytest
from scipy import signal

from quad_model import Environment, Mount, QuadModel, SensorSuite
from quad_model import dynamics as dyn
from quad_model.environment import isa_pressure_pa
from quad_model.frames import STANDARD_GRAVITY_MPS2, ned_to_geodetic, quat_from_euler
from quad_model.model import VehicleTruth
from quad_model.sensors import BaroModel, GpsModel, ImuModel, MagModel, SlotGrid

G = STANDARD_GRAVITY_MPS2


@pytest.fixture(scope="module")
def ideal_imu():
    """IMU errors off except white noise and vibration: the σ tests see only those."""

    def make(vehicle, variant):
        return variant(
            vehicle,
            imu={
                "gyro_bias_random_walk_radps2_per_sqrthz": 0.0,
                "accel_bias_random_walk_mps3_per_sqrthz": 0.0,
                "gyro_turn_on_bias_std_radps": 0.0,
                "accel_turn_on_bias_std_mps2": 0.0,
                "gyro_scale_error_std": 0.0,
                "accel_scale_error_std": 0.0,
                "misalignment_std_rad": 0.0,
                "gyro_bias_tempco_radps_per_k": 0.0,
                "accel_bias_tempco_mps2_per_k": 0.0,
            },
        )

    return make


def imu_record(model, imu, command, seconds):
    accel, gyro = [], []
    for _ in range(round(seconds * imu.rate_hz)):
        model.advance(command, 1.0 / imu.rate_hz)
        sample = imu.sample(model.truth)
        accel.append(sample.accel_mps2)
        gyro.append(sample.gyro_radps)
    return np.array(accel), np.array(gyro)


@pytest.mark.parametrize("rate_hz", [1000.0, 250.0])
def test_imu_white_noise_is_density_times_sqrt_rate(f450, variant, ideal_imu, rate_hz):
    vehicle = ideal_imu(f450, variant)
    model = QuadModel(vehicle, np.random.default_rng(1))  # resting, motors off: no vibration
    imu = ImuModel(vehicle, model.environment, np.random.default_rng(2), rate_hz)
    accel, gyro = imu_record(model, imu, [0.0] * 4, 4000 / rate_hz)
    # MPU-6000 datasheet: 0.005 °/s/√Hz and 400 µg/√Hz.
    gyro_sigma = math.radians(0.005) * math.sqrt(rate_hz)
    accel_sigma = 400e-6 * G * math.sqrt(rate_hz)
    # 4000 samples: the standard deviation is known to ±1.1 % (1σ); allow 4σ.
    np.testing.assert_allclose(gyro.std(axis=0), gyro_sigma, rtol=0.045)
    np.testing.assert_allclose(accel.std(axis=0), accel_sigma, rtol=0.045)
    np.testing.assert_allclose(
        accel.mean(axis=0), [0, 0, -G], atol=4 * accel_sigma / math.sqrt(4000)
    )


def test_imu_white_noise_axis_gains_scale_each_sensor_axis(f450, variant, ideal_imu):
    """σ of axis a = density·√rate·gain[a] (the X500's accelerometer z is half as noisy)."""
    gains = {"gyro_noise_axis_gain": (0.5, 1.0, 2.0), "accel_noise_axis_gain": (1.5, 1.0, 0.5)}
    vehicle = variant(ideal_imu(f450, variant), imu=gains)
    model = QuadModel(vehicle, np.random.default_rng(1))
    imu = ImuModel(vehicle, model.environment, np.random.default_rng(2), 1000.0)
    accel, gyro = imu_record(model, imu, [0.0] * 4, 4.0)
    gyro_sigma = math.radians(0.005) * math.sqrt(1000.0)
    accel_sigma = 400e-6 * G * math.sqrt(1000.0)
    gyro_want = np.multiply(gyro_sigma, gains["gyro_noise_axis_gain"])
    accel_want = np.multiply(accel_sigma, gains["accel_noise_axis_gain"])
    np.testing.assert_allclose(gyro.std(axis=0), gyro_want, rtol=0.045)
    np.testing.assert_allclose(accel.std(axis=0), accel_want, rtol=0.045)


def test_vibration_raises_imu_noise_when_motors_spin(f450, variant, ideal_imu):
    vehicle = ideal_imu(f450, variant)
    vib = vehicle.vibration
    model = QuadModel(vehicle, np.random.default_rng(3), mount=Mount.THRUST_STAND)
    imu = ImuModel(vehicle, model.environment, np.random.default_rng(4))
    rest_accel, rest_gyro = imu_record(model, imu, [0.0] * 4, 2.0)
    # Spin near hover, the vibration's reference speed (the paper's step from 0 to ~50 %);
    # real rotors never turn at exactly equal speeds, so their tones beat.
    command = model.hover_throttle() * np.array([1.0, 1.01, 0.99, 1.02])
    model.advance(command, 0.3)
    spin_accel, spin_gyro = imu_record(model, imu, command, 4.0)
    ratio_sq = (model.truth.rotor_speed_radps / vib.reference_rotor_speed_radps) ** 2

    def expected_std(harmonics, broadband, gain, white):
        tones = sum(np.sum((a * ratio_sq) ** 2) / 2 for a in harmonics)
        return np.sqrt((tones + broadband**2 * np.mean(ratio_sq**2)) * np.square(gain) + white**2)

    accel_expected = expected_std(
        vib.accel_harmonic_amplitude_mps2,
        vib.accel_broadband_std_mps2,
        vib.accel_axis_gain,
        imu.accel_noise_std_mps2,
    )
    gyro_expected = expected_std(
        vib.gyro_harmonic_amplitude_radps,
        vib.gyro_broadband_std_radps,
        vib.gyro_axis_gain,
        imu.gyro_noise_std_radps,
    )
    assert np.all(spin_accel.std(axis=0) > 3 * rest_accel.std(axis=0))
    assert np.all(spin_gyro.std(axis=0) > 1.5 * rest_gyro.std(axis=0))  # z is quiet (gain 0.5)
    np.testing.assert_allclose(spin_accel.std(axis=0), accel_expected, rtol=0.1)
    np.testing.assert_allclose(spin_gyro.std(axis=0), gyro_expected, rtol=0.1)
    # The strongest lines in the accelerometer spectrum sit at the rotors' shaft rates.
    shaft_hz = model.truth.rotor_speed_radps / (2 * math.pi)
    freqs, psd = signal.welch(spin_accel[:, 0], fs=imu.rate_hz, nperseg=2000)
    peak_hz = freqs[np.argmax(psd)]
    assert shaft_hz.min() - 1.0 <= peak_hz <= shaft_hz.max() + 1.0


def test_sensors_are_deterministic_by_seed(f450):
    def run(seed):
        model = QuadModel(f450, np.random.default_rng(seed), mount=Mount.THRUST_STAND)
        suite = SensorSuite(f450, model.environment, np.random.default_rng(seed))
        values = []
        for _ in range(300):
            model.advance([0.55] * 4, 0.001)
            readings = suite.sample(model.truth)
            values.append(readings.imu.accel_mps2)
            values.append(readings.imu.gyro_radps)
            if readings.baro:
                values.append([readings.baro.pressure_pa])
            if readings.mag:
                values.append(readings.mag.field_gauss)
            if readings.gps:
                values.append([readings.gps.lat_deg, readings.gps.lon_deg])
        return np.concatenate(values)

    first = run(11)
    np.testing.assert_array_equal(first, run(11))
    assert not np.array_equal(first, run(12))


def test_suite_schedules_each_sensor_at_its_rate(f450):
    model = QuadModel(f450, np.random.default_rng(1))
    suite = SensorSuite(f450, model.environment, np.random.default_rng(1))
    counts = dict.fromkeys(("imu", "mag", "baro", "gps"), 0)
    for frame in range(2000):  # 2 s of 1 ms frames, t = 0 … 1.999 s
        if frame:
            model.advance([0.0] * 4, 0.001)
        readings = suite.sample(model.truth)
        for name in counts:
            counts[name] += getattr(readings, name) is not None
    assert counts == {"imu": 2000, "mag": 200, "baro": 100, "gps": 19}  # GPS: 110 ms latency


def test_baro_reads_isa_pressure_with_its_noise(f450, variant):
    vehicle = variant(f450, baro={"drift_random_walk_pa_per_sqrts": 0.0})
    model = QuadModel(vehicle, np.random.default_rng(1))
    model.reset(position_ned_m=(0, 0, -100), rotor_speed_radps=[0.0] * 4)
    baro = BaroModel(vehicle, model.environment, np.random.default_rng(2))
    truth = model.truth
    pressures = np.array([baro.sample(truth).pressure_pa for _ in range(2000)])
    expected = isa_pressure_pa(model.environment.home.alt_amsl_m + 100.0)
    assert pressures.mean() == pytest.approx(expected, abs=4 * 1.2 / math.sqrt(2000))
    assert pressures.std() == pytest.approx(1.2, rel=0.07)  # MS5611 0.012 mbar RMS
    sample = baro.sample(truth)
    assert sample.temperature_degc == pytest.approx(15.0 - 0.0065 * 588.0 + 10.0)


def test_baro_drift_is_a_random_walk(f450):
    env = Environment()
    finals = []
    for seed in range(200):
        baro = BaroModel(f450, env, np.random.default_rng(seed))
        baro.sample(_moving_truth(0.0))
        finals.append(baro.sample(_moving_truth(100.0)).pressure_pa)
    # After 100 s: σ² = (0.3 Pa/√s)²·100 s + (1.2 Pa)².
    assert np.std(finals) == pytest.approx(math.sqrt(0.09 * 100 + 1.44), rel=0.15)


def test_magnetometer_rotates_earth_field_into_the_body(f450, variant):
    vehicle = variant(f450, mag={"noise_std_gauss": 0.0})
    model = QuadModel(vehicle, np.random.default_rng(1))
    mag = MagModel(vehicle, model.environment, np.random.default_rng(2))
    north, east, down = model.environment.magnetic_field.ned_gauss()
    hard_iron = np.array(vehicle.mag.hard_iron_frd_gauss)
    np.testing.assert_allclose(
        mag.sample(model.truth).field_gauss, np.array([north, east, down]) + hard_iron
    )
    model.reset(attitude_quat=quat_from_euler(0.0, 0.0, math.pi / 2))  # facing east
    np.testing.assert_allclose(
        mag.sample(model.truth).field_gauss, np.array([east, -north, down]) + hard_iron, atol=1e-12
    )


def _truth_at_us(time_us: int) -> VehicleTruth:
    """A vehicle at rest on the ground at ``time_us``."""
    state = np.zeros(dyn.X_SIZE)
    state[dyn.X_TIME_US] = time_us
    state[dyn.X_QUAT] = 1.0
    return VehicleTruth(state, np.zeros(dyn.A_SIZE), rotors=4)


def _moving_truth(time_s: float) -> VehicleTruth:
    """Level flight east at 5 m/s, 10 m up: a truth with known position at every time."""
    state = np.zeros(dyn.X_SIZE)
    state[dyn.X_TIME_US] = round(time_s * 1e6)
    state[dyn.X_POS : dyn.X_POS + 3] = [0.0, 5.0 * time_s, -10.0]
    state[dyn.X_VEL : dyn.X_VEL + 3] = [0.0, 5.0, 0.0]
    state[dyn.X_QUAT] = 1.0
    return VehicleTruth(state, np.zeros(dyn.A_SIZE), rotors=4)


def test_gps_latency_fix_rate_and_position(f450, variant):
    vehicle = variant(
        f450,
        gps={
            "horizontal_error_std_m": 0.0,
            "vertical_error_std_m": 0.0,
            "velocity_noise_std_mps": 0.0,
        },
    )
    env = Environment()
    gps = GpsModel(vehicle, env, np.random.default_rng(1))
    fixes = [gps.sample(_moving_truth(k * 0.001)) for k in range(3001)]
    delivered = [(k, fix) for k, fix in enumerate(fixes) if fix is not None]
    assert len(delivered) == 29  # 10 Hz, each 110 ms after its epoch: 0.11 … 2.91 s
    k, fix = delivered[0]
    assert k == 110
    assert fix.time_us == 110_000
    k, fix = delivered[5]
    assert fix.time_us == 610_000
    # The fix describes where the vehicle was at its epoch (0.5 s), not where it is now.
    lat, lon, alt = ned_to_geodetic(
        [0.0, 2.5, -10.0], env.home.lat_deg, env.home.lon_deg, env.home.alt_amsl_m
    )
    assert (fix.lat_deg, fix.lon_deg, fix.alt_amsl_m) == pytest.approx((lat, lon, alt), abs=1e-9)
    np.testing.assert_allclose(fix.vel_ned_mps, [0.0, 5.0, 0.0])
    assert fix.fix_type == 3
    assert fix.satellites_visible == vehicle.gps.satellites_visible


def test_gps_position_error_has_configured_spread(f450):
    env = Environment()
    errors = []
    for seed in range(300):
        gps = GpsModel(f450, env, np.random.default_rng(seed))
        fix = gps.sample(_moving_truth(0.11))
        errors.append([fix.alt_amsl_m - (env.home.alt_amsl_m + 10.0)])
    assert np.std(errors) == pytest.approx(f450.gps.vertical_error_std_m, rel=0.15)


def test_model_time_is_exact_whole_microseconds_at_every_frame(f450):
    """13 steps of 192.3 µs (a 5200 Hz model under a 400 Hz IMU) end each 2.5 ms frame on a
    whole µs: the model counts steps, it does not sum float durations (a float sum drifted
    past a sensor slot after 575 s and an IMU sample went missing)."""
    model = QuadModel(f450, np.random.default_rng(0), physics_rate_hz=5200)
    model.reset(time_us=86_400_000_000)  # a day in: float seconds would have drifted by now
    for frame in range(1, 2001):
        model.advance([0.0] * 4, 0.0025)
        assert model.truth.time_us == 86_400_000_000 + frame * 2500
    assert model.truth.time_s == 86_405.0


@pytest.mark.parametrize("rate_hz", [250.0, 400.0, 1000.0, 8.5, 7.0, 3.0])
def test_slot_grid_keeps_its_slots_for_a_day(rate_hz):
    """Slot k is due at ⌈k·10⁶/rate⌉ µs, also after 24 h and for rates that do not divide 1 s."""
    grid = SlotGrid(rate_hz)
    for slot in (0, 1, 2, 3, round(86_400 * rate_hz) - 1, round(86_400 * rate_hz)):
        due_us = grid.time_of(slot)
        assert due_us == math.ceil(Fraction(slot) * 1_000_000 / Fraction(rate_hz))
        assert grid.slot_at(due_us) == slot
        assert grid.slot_at(due_us - 1) == slot - 1
    assert grid.time_of(round(86_400 * rate_hz)) == 86_400_000_000


def test_every_imu_slot_is_sampled_at_frames_a_day_into_a_run(f450):
    suite = SensorSuite(f450, Environment(), np.random.default_rng(0), imu_rate_hz=250.0,
                        mag_rate_hz=100.0, baro_rate_hz=50.0)  # fmt: skip
    start_us = 86_400_000_000
    due = {"imu": 0, "mag": 0, "baro": 0}
    for frame in range(1000):  # 4 s of 4 ms frames
        readings = suite.sample(_truth_at_us(start_us + frame * 4000))
        for name in due:
            due[name] += getattr(readings, name) is not None
    assert due == {"imu": 1000, "mag": 400, "baro": 200}
