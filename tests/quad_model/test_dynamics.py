"""Rigid-body, propulsion and contact physics against closed-form cases."""

import math

import control
import numba
import numpy as np
import pytest

from quad_model import Environment, ModelInputError, Mount, QuadBatch, QuadModel, Wind
from quad_model import dynamics as dyn
from quad_model.environment import isa_density_kgpm3
from quad_model.frames import STANDARD_GRAVITY_MPS2, euler_from_quat, quat_from_euler, quat_to_dcm
from quad_model.model import PARALLEL_MIN_VEHICLES, charge_used_for_voltage_c, pack_params

G = STANDARD_GRAVITY_MPS2
HOME_ALT_M = Environment().home.alt_amsl_m


def density_ratio(vehicle, down_m: float = 0.0) -> float:
    return isa_density_kgpm3(HOME_ALT_M - down_m) / vehicle.propulsion.reference_air_density_kgpm3


def test_hover_equilibrium_at_predicted_rotor_speed(f450, rng):
    model = QuadModel(f450, rng)
    ct = f450.propulsion.thrust_coefficient_n_per_radps2 * density_ratio(f450, -10.0)
    predicted = math.sqrt(f450.body.mass_kg * G / (4 * ct))
    model.reset(position_ned_m=(0, 0, -10), rotor_speed_radps=[predicted] * 4)
    model.advance([model.hover_throttle()] * 4, 0.5)
    truth = model.truth
    np.testing.assert_allclose(truth.rotor_speed_radps, predicted, rtol=2e-4)
    assert truth.rotor_thrust_n.sum() == pytest.approx(f450.body.mass_kg * G, rel=5e-4)
    np.testing.assert_allclose(truth.velocity_ned_mps, 0.0, atol=5e-3)
    np.testing.assert_allclose(truth.position_ned_m, [0, 0, -10], atol=2e-3)
    # Hovering, the accelerometer reads the weight: (0, 0, -g).
    np.testing.assert_allclose(truth.specific_force_frd_mps2, [0, 0, -G], atol=5e-3)


def test_free_fall_without_drag_is_half_g_t_squared(f450_no_drag, rng):
    model = QuadModel(f450_no_drag, rng)
    model.reset(position_ned_m=(0, 0, -100), velocity_ned_mps=(1.0, -2.0, 0.0))
    model.advance([0.0] * 4, 2.0)
    truth = model.truth
    np.testing.assert_allclose(truth.position_ned_m, [2.0, -4.0, -100 + 0.5 * G * 4.0], atol=1e-9)
    np.testing.assert_allclose(truth.velocity_ned_mps, [1.0, -2.0, 2.0 * G], atol=1e-9)
    # Free fall: the accelerometer reads zero.
    np.testing.assert_allclose(truth.specific_force_frd_mps2, 0.0, atol=1e-9)


def test_falling_body_reaches_drag_terminal_velocity(f450, rng):
    model = QuadModel(f450, rng)
    model.reset(position_ned_m=(0, 0, -2000))
    model.advance([0.0] * 4, 12.0)
    truth = model.truth
    drag_area = f450.body.drag_area_m2[2]
    terminal = math.sqrt(2 * f450.body.mass_kg * G / (truth.air_density_kgpm3 * drag_area))
    assert truth.velocity_ned_mps[2] == pytest.approx(terminal, rel=2e-3)


def test_torque_free_spin_conserves_angular_momentum_and_energy(f450_no_drag, rng):
    model = QuadModel(f450_no_drag, rng)
    rate = np.array([0.5, 3.0, 0.8])  # mostly the intermediate axis: it tumbles
    model.reset(position_ned_m=(0, 0, -500), angular_rate_frd_radps=rate)
    inertia = np.array(f450_no_drag.body.inertia_kgm2)

    def momentum_and_energy(truth):
        w = truth.angular_rate_frd_radps
        return quat_to_dcm(truth.attitude_quat) @ (inertia @ w), 0.5 * w @ inertia @ w

    momentum0, energy0 = momentum_and_energy(model.truth)
    model.advance([0.0] * 4, 3.0)
    momentum, energy = momentum_and_energy(model.truth)
    assert not np.allclose(model.truth.angular_rate_frd_radps, rate, atol=0.1)  # it did tumble
    np.testing.assert_allclose(momentum, momentum0, rtol=0, atol=1e-9 * np.linalg.norm(momentum0))
    assert energy == pytest.approx(energy0, rel=1e-9)


def test_yaw_spin_up_from_rotor_torque_matches_izz(f450_no_drag, rng, variant):
    # Rotor speeds held (very slow motors): CCW rotors faster, same total thrust.
    vehicle = variant(f450_no_drag, propulsion={"motor_time_constant_s": 1e9})
    hover = vehicle.hover_rotor_speed_radps / math.sqrt(density_ratio(vehicle, -50.0))
    eps = 0.05
    fast, slow = hover * math.sqrt(1 + eps), hover * math.sqrt(1 - eps)
    model = QuadModel(vehicle, rng)
    model.reset(position_ned_m=(0, 0, -50), rotor_speed_radps=[fast, fast, slow, slow])
    model.advance([0.0] * 4, 0.5)
    cq = vehicle.propulsion.torque_coefficient_nm_per_radps2 * density_ratio(vehicle, -50.0)
    yaw_moment = cq * 2 * (fast**2 - slow**2)
    izz = vehicle.body.inertia_kgm2[2][2]
    rate = model.truth.angular_rate_frd_radps
    # PX4 convention: faster CCW rotors yaw the body clockwise seen from above, +z in FRD.
    assert rate[2] == pytest.approx(yaw_moment / izz * 0.5, rel=1e-6)
    np.testing.assert_allclose(rate[:2], 0.0, atol=1e-9)
    assert euler_from_quat(model.truth.attitude_quat)[2] == pytest.approx(
        0.5 * yaw_moment / izz * 0.5**2, rel=1e-6
    )
    np.testing.assert_allclose(model.truth.velocity_ned_mps, 0.0, atol=1e-6)


def test_axial_inflow_takes_thrust_in_a_climb_and_gives_it_in_a_descent(x500, variant):
    """Blade element and momentum theory, linear in the axial speed: each rotor's thrust is
    k_T·ω² - k·ω·V along its axis; 1 ms at ±2 m/s (the speed changes by < 1 cm/s)."""
    k = x500.propulsion.axial_inflow_coefficient_ns_per_m_rad
    assert k == pytest.approx(3.85e-4)
    without = variant(x500, propulsion={"axial_inflow_coefficient_ns_per_m_rad": 0.0})
    for climb_mps in (2.0, -2.0):
        thrusts = []
        for vehicle in (x500, without):
            model = QuadModel(vehicle, np.random.default_rng(1))
            model.reset(position_ned_m=(0, 0, -10), velocity_ned_mps=(0, 0, -climb_mps),
                        rotor_speed_radps=[760.0] * 4)  # fmt: skip
            model.advance([model.hover_throttle()] * 4, 0.001)
            thrusts.append(model.truth.rotor_thrust_n)
            omega = model.truth.rotor_speed_radps
        np.testing.assert_allclose(thrusts[1] - thrusts[0], k * omega * climb_mps, rtol=0.01)


def test_motor_speed_is_a_first_order_lag(f450, rng, variant):
    # A stiff battery keeps the speed target fixed while the rotors spin up.
    vehicle = variant(f450, battery={"internal_resistance_ohm": 0.0})
    model = QuadModel(vehicle, rng, mount=Mount.THRUST_STAND)
    throttle = 0.6
    tau = vehicle.propulsion.motor_time_constant_s
    model.advance([throttle] * 4, tau)
    prop = vehicle.propulsion
    target = (prop.speed_slope_radps * throttle + prop.speed_offset_radps) * (
        model.truth.battery_voltage_v / prop.speed_curve_voltage_v
    )
    np.testing.assert_allclose(
        model.truth.rotor_speed_radps, target * (1 - math.exp(-1)), rtol=2e-4
    )


def test_thrust_stand_reads_rotor_thrust_and_torque(f450, rng):
    model = QuadModel(f450, rng, mount=Mount.THRUST_STAND)
    model.advance([0.2, 0.4, 0.6, 0.8], 0.5)  # 25 motor time constants: steady
    truth = model.truth
    w = truth.rotor_speed_radps
    ratio = density_ratio(f450)
    thrust = f450.propulsion.thrust_coefficient_n_per_radps2 * ratio * w**2
    torque = f450.propulsion.torque_coefficient_nm_per_radps2 * ratio * w**2
    np.testing.assert_allclose(truth.rotor_thrust_n, thrust, rtol=1e-12)
    np.testing.assert_allclose(truth.rotor_torque_nm, torque, rtol=1e-12)
    positions = np.array(f450.propulsion.position_frd_m)
    spin = np.array(f450.propulsion.spin_direction)
    expected_moment = np.array(
        [
            -(positions[:, 1] * thrust).sum(),  # y × (-T): right rotors roll left
            (positions[:, 0] * thrust).sum(),  # front rotors pitch up
            (spin * torque).sum(),
        ]
    )
    np.testing.assert_allclose(truth.force_frd_n, [0, 0, -thrust.sum()], atol=1e-12)
    # rtol: the draining battery still slows the rotors a little (J_r·ω̇ reaction).
    np.testing.assert_allclose(truth.moment_frd_nm, expected_moment, rtol=5e-4)
    # Held still: position, attitude and rates do not move.
    np.testing.assert_allclose(truth.position_ned_m, 0.0)
    np.testing.assert_allclose(truth.attitude_quat, [1, 0, 0, 0])


def test_battery_sags_with_current_and_limits_speed(f450, rng):
    model = QuadModel(f450, rng, mount=Mount.THRUST_STAND)
    model.advance([0.0] * 4, 0.01)
    idle = model.truth
    battery = f450.battery
    assert idle.battery_voltage_v == pytest.approx(
        battery.cell_count * battery.cell_full_v, rel=2e-3
    )  # avionics only
    model.advance([1.0] * 4, 0.3)
    full = model.truth
    emf = battery.cell_count * battery.cell_full_v - 0.0  # charge used is tiny here
    assert full.battery_voltage_v == pytest.approx(
        emf - battery.internal_resistance_ohm * full.battery_current_a, rel=2e-3
    )
    shaft_w = (full.rotor_torque_nm * full.rotor_speed_radps).sum()
    electrical_w = shaft_w / battery.propulsion_efficiency + battery.avionics_power_w
    assert full.battery_current_a == pytest.approx(electrical_w / full.battery_voltage_v, rel=1e-9)
    prop = f450.propulsion
    full_speed = (prop.speed_slope_radps + prop.speed_offset_radps) * (
        full.battery_voltage_v / prop.speed_curve_voltage_v
    )
    np.testing.assert_allclose(full.rotor_speed_radps, full_speed, rtol=1e-4)
    assert full.battery_charge_used_c > 0.0


def test_open_circuit_voltage_law_round_trips_through_charge_used(x500, f450):
    # X500 pack: 4S, 3.5..4.2 V/cell, 5 Ah. 15.2 V is SoC (15.2 - 14.0)/(16.8 - 14.0) = 3/7,
    # so 4/7 of 18 000 C is already drawn.
    assert charge_used_for_voltage_c(x500.battery, 15.2) == pytest.approx(18000 * 4 / 7, rel=1e-12)
    for vehicle in (x500, f450):
        battery = vehicle.battery
        params = dyn.lane_block(pack_params(vehicle, Environment()))
        empty_v, full_v = (
            battery.cell_count * v for v in (battery.cell_empty_v, battery.cell_full_v)
        )
        for voltage in np.linspace(empty_v, full_v, 7):
            charge = charge_used_for_voltage_c(battery, float(voltage))
            assert dyn.open_circuit_voltage(params, 0, charge) == pytest.approx(voltage, rel=1e-12)
        assert charge_used_for_voltage_c(battery, full_v) == 0.0
        assert charge_used_for_voltage_c(battery, empty_v) == pytest.approx(
            battery.capacity_ah * 3600.0, rel=1e-12
        )


def test_model_starts_from_a_given_battery_voltage(x500, rng):
    model = QuadModel(x500, rng, mount=Mount.THRUST_STAND)
    full_hover = model.hover_throttle()
    model.reset(battery_voltage_v=15.2)
    model.advance([0.0] * 4, 0.01)
    battery = x500.battery
    # At rest only the avionics load: V = E - R·P/V, E = 15.2 V (the upper root).
    emf, resistance = 15.2, battery.internal_resistance_ohm
    rest_v = 0.5 * (emf + math.sqrt(emf**2 - 4 * resistance * battery.avionics_power_w))
    assert model.truth.battery_voltage_v == pytest.approx(rest_v, rel=1e-6)
    assert model.truth.battery_charge_used_c == pytest.approx(18000 * 4 / 7, rel=1e-6)
    # A lower pack needs more throttle for the same hover speed: the ESC curve scales with V.
    assert model.hover_throttle() > full_hover


@pytest.mark.parametrize("voltage", [13.9, 16.9, math.nan])
def test_battery_voltage_outside_the_pack_range_is_refused(x500, rng, voltage):
    model = QuadModel(x500, rng)
    with pytest.raises(ModelInputError) as error:
        model.reset(battery_voltage_v=voltage)
    assert str(error.value) == (
        f"battery_voltage_v={voltage:g} V is outside the pack's open-circuit range "
        "14..16.8 V (4 cells × 3.5..4.2 V)"
    )


def test_ground_contact_holds_and_landing_does_not_bounce(f450, rng):
    model = QuadModel(f450, rng)
    # Starts resting on the ground; 80 % of hover thrust cannot lift it.
    model.advance([0.0] * 4, 0.2)
    low = 0.8 * model.hover_throttle()
    for _ in range(500):
        model.advance([low] * 4, 0.002)
        truth = model.truth
        assert truth.position_ned_m[2] == 0.0
        assert truth.on_ground
    np.testing.assert_allclose(truth.velocity_ned_mps, 0.0)
    np.testing.assert_allclose(truth.specific_force_frd_mps2, [0, 0, -G], atol=1e-12)
    # Dropped from 2 m with motors off: it stops on the ground and stays there.
    model.reset(position_ned_m=(0, 0, -2))
    heights, speeds, accels, forces = [], [], [], []
    for _ in range(1500):
        model.advance([0.0] * 4, 0.001)
        heights.append(model.truth.position_ned_m[2])
        speeds.append(model.truth.velocity_ned_mps[2])
        accels.append(model.truth.acceleration_ned_mps2[2])
        forces.append(model.truth.specific_force_frd_mps2[2])
    heights, speeds = np.array(heights), np.array(speeds)
    touchdown = int(np.argmax(heights >= 0.0))
    assert heights.max() == 0.0  # never below the ground
    assert 0.55 < touchdown * 1e-3 < 0.7  # √(2h/g) = 0.64 s (less with drag)
    np.testing.assert_array_equal(heights[touchdown:], 0.0)  # no bounce
    # The legs stop it with the accelerometer feeling it: the accelerations reported from
    # the touchdown on add up to the speed it hit with (Δv = ∫a dt), and the legs push
    # with LANDING_DECELERATION_MPS2 against what the fall still adds (gravity less the
    # drag: the acceleration of the frame before the touchdown). The drag falls off as the
    # vehicle slows, so the stop takes a little longer than at the impact's net rate.
    impact, falling = speeds[touchdown - 1], accels[touchdown - 1]
    legs = dyn.LANDING_DECELERATION_MPS2
    assert sum(accels[touchdown:]) * 1e-3 == pytest.approx(-impact, rel=1e-9)
    stopped = touchdown + int(np.argmax(speeds[touchdown:] == 0.0))
    assert (stopped - touchdown) * 1e-3 == pytest.approx(impact / (legs - falling), rel=0.05)
    # specific force = a − g: the legs' push plus the drag's, largest at the impact
    assert min(forces) == pytest.approx(-(legs + G - falling), rel=1e-3)
    np.testing.assert_array_equal(accels[stopped + 1 :], 0.0)
    # Enough thrust lifts it off.
    model.advance([1.2 * model.hover_throttle()] * 4, 1.0)
    assert model.truth.position_ned_m[2] < -0.1
    assert not model.truth.on_ground


def test_pitch_gimbal_small_signal_matches_linearized_transfer_function(f450, rng):
    model = QuadModel(f450, rng, mount=Mount.GIMBAL_PITCH)
    trim = model.hover_throttle()
    model.advance([trim] * 4, 0.5)  # settle rotors and battery at the operating point
    operating = model.truth
    speed0 = operating.rotor_speed_radps[0]
    prop = f450.propulsion
    # θ/δ = K / (s²(τs + 1)): δ raises the front rotors (0, 2) and lowers the rear (1, 3).
    motor_gain = prop.speed_slope_radps * operating.battery_voltage_v / prop.speed_curve_voltage_v
    ct = (
        prop.thrust_coefficient_n_per_radps2
        * operating.air_density_kgpm3
        / prop.reference_air_density_kgpm3
    )
    arm_x = prop.position_frd_m[0][0]
    gain = 4 * arm_x * 2 * ct * speed0 * motor_gain / f450.body.inertia_kgm2[1][1]
    plant = control.tf([gain], [prop.motor_time_constant_s, 1, 0, 0])

    dt, amplitude = 0.001, 0.001
    time = np.arange(0, 0.8, dt)
    doublet = np.where(time < 0.2, amplitude, np.where(time < 0.4, -amplitude, 0.0))
    pitch = []
    for delta in doublet:
        model.advance([trim + delta, trim - delta, trim + delta, trim - delta], dt)
        pitch.append(euler_from_quat(model.truth.attitude_quat)[1])
    # The model holds each command over the frame and reports the end of it: a ZOH plant.
    response = control.forced_response(control.c2d(plant, dt, "zoh"), T=time, U=doublet)
    # pitch[k] is at the end of frame k, the ZOH response's sample k + 1.
    linear = response.outputs[1:]
    assert np.max(np.abs(linear)) > 0.015  # a real motion, about 1°
    # 1 %: the quadratic aerodynamic damping, absent from the linearization, is that small.
    np.testing.assert_allclose(pitch[:-1], linear, atol=0.01 * np.max(np.abs(linear)))


def test_roll_gimbal_leaves_only_roll_free(f450, rng):
    model = QuadModel(f450, rng, mount=Mount.GIMBAL_ROLL)
    model.advance([0.7, 0.5, 0.5, 0.7], 0.3)  # right rotors (0, 3) stronger: roll left
    roll, pitch, yaw = euler_from_quat(model.truth.attitude_quat)
    assert roll < -0.1
    assert pitch == 0.0
    assert yaw == 0.0
    np.testing.assert_allclose(model.truth.position_ned_m, 0.0)


def test_motor_health_hook_scales_thrust(f450, rng):
    model = QuadModel(f450, rng, mount=Mount.THRUST_STAND)
    model.set_motor_health(2, 0.5)
    model.set_motor_health(3, 0.0)
    model.advance([0.6] * 4, 0.5)
    thrust = model.truth.rotor_thrust_n
    assert thrust[2] / thrust[0] == pytest.approx(0.5, rel=1e-3)
    assert thrust[3] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(model.motor_health, [1.0, 1.0, 0.5, 0.0])
    with pytest.raises(ModelInputError, match=r"thrust_fraction=1.5 must be within 0..1"):
        model.set_motor_health(0, 1.5)


def test_batch_matches_single_vehicle_serial_and_parallel(f450, x500):
    # Bit for bit: a lone vehicle runs the kernel's scalar loop, a batch its SIMD loop
    # (LANES vehicles per instruction) and, from PARALLEL_MIN_VEHICLES on, both cores. No
    # fastmath, so every lane does the same IEEE operations in the same order.
    commands = np.array([0.62, 0.60, 0.61, 0.63])
    single = QuadModel(f450, np.random.default_rng(1))
    single.reset(position_ned_m=(0, 0, -5), rotor_speed_radps=[560.0] * 4)
    single.set_motor_health(1, 0.8)
    single.advance(commands, 0.5)
    single.advance(commands * 1.05, 0.013)
    assert PARALLEL_MIN_VEHICLES <= 40
    for count in (3, dyn.LANES + 3, 40):  # a part chunk; a whole and a part; all cores
        vehicles = [f450] * (count - 1) + [x500]
        batch = QuadBatch(vehicles, count, np.random.default_rng(1))
        batch.reset(position_ned_m=(0, 0, -5), rotor_speed_radps=[560.0] * 4)
        for k in range(count):
            batch.set_motor_health(k, 1, 0.8)
        batch.advance(np.tile(commands, (count, 1)), 0.5)
        batch.advance(np.tile(commands * 1.05, (count, 1)), 0.013)
        for k in range(count - 1):
            np.testing.assert_array_equal(batch.states[k], single._batch.states[0])
            np.testing.assert_array_equal(batch.outputs[k], single._batch.outputs[0])
        assert not np.array_equal(batch.states[-1], batch.states[0])  # the X500 differs


def test_batch_gives_the_same_numbers_on_one_or_two_threads(f450):
    # The QuadBatch promise: a seed gives the same numbers on any core count (turbulence on,
    # so the noise is drawn too).
    env = Environment(wind=Wind(steady_ned_mps=(3.0, 1.0, 0.0), wind_at_6m_mps=8.0))
    assert 5 * dyn.LANES >= PARALLEL_MIN_VEHICLES  # the batch runs the parallel kernel
    runs = []
    for threads in (1, 2):
        batch = QuadBatch(f450, 5 * dyn.LANES, np.random.default_rng(9), env)
        batch.reset(position_ned_m=(0, 0, -10), rotor_speed_radps=[560.0] * 4)
        previous = numba.get_num_threads()
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        try:
            batch.advance(np.full((batch.count, 4), 0.6), 0.05)
        finally:
            numba.set_num_threads(previous)
        runs.append((batch.states.copy(), batch.outputs.copy()))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    assert np.ptp(runs[0][1][:, dyn.A_WIND_NED]) > 0.0  # the vehicles saw different gusts


def test_dryden_turbulence_intensity_and_determinism(f450):
    steady = 20.0
    env = Environment(wind=Wind(steady_ned_mps=(steady, 0.0, 0.0), wind_at_6m_mps=15.0))
    model = QuadModel(f450, np.random.default_rng(5), env, mount=Mount.THRUST_STAND)
    wind = []
    for _ in range(3000):
        model.advance([0.0] * 4, 0.05)
        wind.append(model.truth.wind_ned_mps)
    wind = np.array(wind)
    # MIL-F-8785C at the 10 ft floor: σ_w = 0.1·W20, σ_u = σ_w / (0.177 + 0.000823·10)^0.4.
    sigma_w = 1.5
    sigma_u = sigma_w / (0.177 + 0.000823 * 10) ** 0.4
    assert wind[:, 0].mean() == pytest.approx(steady, abs=0.6)
    assert wind[:, 0].std() == pytest.approx(sigma_u, rel=0.2)  # τ_u ≈ 1.2 s: few samples
    assert wind[:, 1].std() == pytest.approx(sigma_u, rel=0.2)
    assert wind[:, 2].std() == pytest.approx(sigma_w, rel=0.1)  # τ_w ≈ 0.15 s
    again = QuadModel(f450, np.random.default_rng(5), env, mount=Mount.THRUST_STAND)
    again.advance([0.0] * 4, 0.05)
    first = QuadModel(f450, np.random.default_rng(5), env, mount=Mount.THRUST_STAND)
    first.advance([0.0] * 4, 0.05)
    np.testing.assert_array_equal(again.truth.wind_ned_mps, first.truth.wind_ned_mps)
    other = QuadModel(f450, np.random.default_rng(6), env, mount=Mount.THRUST_STAND)
    other.advance([0.0] * 4, 0.05)
    assert not np.array_equal(other.truth.wind_ned_mps, first.truth.wind_ned_mps)


def test_bad_model_inputs_are_refused(f450, rng):
    model = QuadModel(f450, rng)
    with pytest.raises(
        ModelInputError, match=r"^duration_s=0.0013 is not a whole number of 0.2 ms"
    ):
        model.advance([0.5] * 4, 0.0013)
    with pytest.raises(ModelInputError, match=r"^throttles contain a non-finite value"):
        model.advance([0.5, math.nan, 0.5, 0.5], 0.001)
    with pytest.raises(ModelInputError, match=r"^command \[0.5, 0.5\] is not 4 throttles"):
        model.advance([0.5, 0.5], 0.001)
    with pytest.raises(ModelInputError, match=r"below the ground"):
        model.reset(position_ned_m=(0, 0, 1))
    with pytest.raises(ModelInputError, match=r"not a unit quaternion"):
        model.reset(attitude_quat=(1, 1, 0, 0))
    assert model.truth.time_us == 0


def test_initial_state_rests_level_on_the_ground(f450, rng):
    truth = QuadModel(f450, rng).truth
    assert truth.on_ground
    np.testing.assert_allclose(truth.specific_force_frd_mps2, [0, 0, -G], atol=1e-12)
    np.testing.assert_allclose(
        quat_to_dcm(truth.attitude_quat), quat_to_dcm(quat_from_euler(0, 0, 0))
    )
