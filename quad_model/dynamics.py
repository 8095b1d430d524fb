"""The compiled 5 kHz core: a pure derivative, an RK4 substep, and the substep loop.

Why compiled: a 6-DOF step with motors, battery and wind in numpy costs 30-100 µs, while
100× real time at 5 kHz leaves 2 µs. numba compiles the loop so one ``advance()`` is one
call into machine code (``cache=True`` keeps compiled code between runs).

Why flat arrays: numba dispatches a call with a few float64 arrays in well under a
microsecond, whereas a record of twenty named arrays costs several. The layouts below name
every slot once; :mod:`quad_model.model` wraps them in named fields for users.

Why RK4: the stiffest mode is the motor lag (τ ≥ 10 ms); at dt = 0.2 ms RK4's error is far
below the parameter uncertainty, it conserves energy and angular momentum of a torque-free
body to 1e-9 over seconds (tested), and it needs no implicit solve. The quaternion is
renormalized after each step.
"""

import math

import numpy as np
from numba import njit, prange

from quad_model import environment as _env
from quad_model import frames as _frames
from quad_model.frames import STANDARD_GRAVITY_MPS2

ROTORS = 4

# The rotation's entries as numbers (the Python side's convention): a matrix allocated at
# each of the four derivative evaluations per substep cost half the step's time.
_dcm_entries = _frames.dcm_entries

_DRY_AIR_R = _env.DRY_AIR_GAS_CONSTANT


class _Layout:
    """Hands out consecutive slots of a flat array; the one place indices are assigned."""

    def __init__(self) -> None:
        self.size = 0

    def add(self, length: int = 1) -> int:
        start = self.size
        self.size += length
        return start


# Mount: how the vehicle is held (the paper's test benches).
MOUNT_FREE = 0
MOUNT_GIMBAL_PITCH = 1  # 1-DOF bearing through the centre of mass, body y axis
MOUNT_GIMBAL_ROLL = 2  # same, body x axis
MOUNT_THRUST_STAND = 3  # rigidly fixed; the stand reads force and moment

# State: the integrated part first (RK4 over X_DYN slots), then discrete states.
_x = _Layout()
X_POS = _x.add(3)  # position NED, m
X_VEL = _x.add(3)  # velocity NED, m/s
X_QUAT = _x.add(4)  # attitude body→NED, (w, x, y, z)
X_RATE = _x.add(3)  # angular rate FRD, rad/s
X_ROTOR_SPEED = _x.add(ROTORS)  # rad/s, >= 0
X_ROTOR_ANGLE = _x.add(ROTORS)  # rad, in each rotor's own spin direction, wrapped to 2π
X_CHARGE_USED = _x.add(1)  # C drawn from the battery
X_DYN = _x.size
X_TURBULENCE = _x.add(5)  # Dryden shaping-filter states: u, v (2), w (2)
X_ON_GROUND = _x.add(1)  # 1 while resting on the ground
X_TIME_US = _x.add(1)  # simulated time, µs: a whole number (float64 holds it exactly for 285 years)
X_SIZE = _x.size

# Outputs computed at the end of each advance() (not integrated).
_a = _Layout()
A_SPECIFIC_FORCE = _a.add(3)  # FRD, m/s², what an ideal accelerometer reads
A_ACCEL_NED = _a.add(3)  # m/s²
A_VOLTAGE = _a.add(1)  # battery terminal voltage, V
A_CURRENT = _a.add(1)  # battery current, A
A_THRUST = _a.add(ROTORS)  # per rotor, N
A_TORQUE = _a.add(ROTORS)  # per rotor drag torque magnitude, N·m
A_FORCE_FRD = _a.add(3)  # propulsion + aerodynamic force on the body, N
A_MOMENT_FRD = _a.add(3)  # propulsion + aerodynamic moment about the CoM, N·m
A_WIND_NED = _a.add(3)  # wind at the vehicle (steady + turbulence), m/s
A_AIR_DENSITY = _a.add(1)  # kg/m³
A_SIZE = _a.size

# Parameters (one row per vehicle).
_p = _Layout()
P_MASS = _p.add(1)
P_INERTIA = _p.add(9)
P_INERTIA_INV = _p.add(9)
P_DRAG_AREA = _p.add(3)
P_ANGULAR_DRAG = _p.add(3)
P_ROTOR_POS = _p.add(3 * ROTORS)
P_SPIN = _p.add(ROTORS)
P_CT = _p.add(1)
P_CQ = _p.add(1)
P_RHO_REF = _p.add(1)
P_ROTOR_INERTIA = _p.add(1)
P_MOTOR_TAU = _p.add(1)
P_SPEED_SLOPE = _p.add(1)
P_SPEED_OFFSET = _p.add(1)
P_MIN_THROTTLE = _p.add(1)
P_CURVE_VOLTAGE = _p.add(1)
P_ROTOR_DRAG = _p.add(1)
P_CELLS = _p.add(1)
P_CAPACITY_C = _p.add(1)
P_CELL_FULL = _p.add(1)
P_CELL_EMPTY = _p.add(1)
P_R_INTERNAL = _p.add(1)
P_EFFICIENCY = _p.add(1)
P_AVIONICS_W = _p.add(1)
P_HEALTH = _p.add(ROTORS)  # thrust fraction each motor-propeller unit still delivers
P_HOME_ALT = _p.add(1)
P_WIND_STEADY = _p.add(3)
P_W20 = _p.add(1)
P_TEMP_OFFSET = _p.add(1)
P_MOUNT = _p.add(1)
P_SIZE = _p.size

# Dryden (MIL-F-8785C) needs a speed through the air mass; hovering in calm air it would be
# zero, so the correlation time uses at least this speed.
DRYDEN_MIN_AIRSPEED_MPS = 1.0
_FT = 0.3048
_SQRT3 = math.sqrt(3.0)


@njit(cache=True)
def air_density_kgpm3(params: np.ndarray, down_m: float) -> float:
    """Air density at a NED height: ISA pressure with the day's temperature offset."""
    altitude = params[P_HOME_ALT] - down_m
    temperature = _env.isa_temperature_k(altitude) + params[P_TEMP_OFFSET]
    return _env.isa_pressure_pa(altitude) / (_DRY_AIR_R * temperature)


@njit(cache=True)
def open_circuit_voltage(params: np.ndarray, charge_used_c: float) -> float:
    """The pack's EMF: each cell linear in state of charge, full to empty (PX4's model).

    :func:`quad_model.model.charge_used_for_voltage_c` is its inverse.
    """
    soc = min(1.0, max(0.0, 1.0 - charge_used_c / params[P_CAPACITY_C]))
    cell = params[P_CELL_EMPTY] + (params[P_CELL_FULL] - params[P_CELL_EMPTY]) * soc
    return params[P_CELLS] * cell


@njit(cache=True)
def battery_terminal(params: np.ndarray, charge_used_c: float, load_w: float) -> tuple:
    """Terminal voltage and current of the pack delivering ``load_w``.

    V = E - R·I with I = P/V gives V² - E·V + R·P = 0; the upper root is the operating
    point. Past the pack's maximum power (E²/4R) the voltage collapses to E/2.
    """
    emf = open_circuit_voltage(params, charge_used_c)
    disc = emf * emf - 4.0 * params[P_R_INTERNAL] * load_w
    voltage = 0.5 * (emf + math.sqrt(max(disc, 0.0)))
    return voltage, load_w / voltage


@njit(cache=True)
def derivative(x, params, throttle, wind_ned, xdot, aux):
    """Time derivative of the integrated state ``x[:X_DYN]`` (pure: reads only its inputs).

    Writes ``xdot[:X_DYN]`` and, as a by-product, the outputs in ``aux``.
    """
    mount = int(params[P_MOUNT])
    q0, q1, q2, q3 = x[X_QUAT], x[X_QUAT + 1], x[X_QUAT + 2], x[X_QUAT + 3]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _dcm_entries(q0, q1, q2, q3)
    rho = air_density_kgpm3(params, x[X_POS + 2])
    density_ratio = rho / params[P_RHO_REF]

    # Propulsion: shaft power sets the battery load, the battery voltage sets motor speed.
    ct = params[P_CT] * density_ratio
    cq = params[P_CQ] * density_ratio
    shaft_w = 0.0
    for i in range(ROTORS):
        w = x[X_ROTOR_SPEED + i]
        shaft_w += cq * w * w * w
    load_w = shaft_w / params[P_EFFICIENCY] + params[P_AVIONICS_W]
    voltage, current = battery_terminal(params, x[X_CHARGE_USED], load_w)
    voltage_ratio = voltage / params[P_CURVE_VOLTAGE]

    # Air-relative velocity in the body frame.
    va_n = x[X_VEL] - wind_ned[0]
    va_e = x[X_VEL + 1] - wind_ned[1]
    va_d = x[X_VEL + 2] - wind_ned[2]
    vb0 = r00 * va_n + r10 * va_e + r20 * va_d
    vb1 = r01 * va_n + r11 * va_e + r21 * va_d
    vb2 = r02 * va_n + r12 * va_e + r22 * va_d

    # Body drag, quadratic per axis.
    half_rho = 0.5 * rho
    fx = -half_rho * params[P_DRAG_AREA] * abs(vb0) * vb0
    fy = -half_rho * params[P_DRAG_AREA + 1] * abs(vb1) * vb1
    fz = -half_rho * params[P_DRAG_AREA + 2] * abs(vb2) * vb2
    mx = 0.0
    my = 0.0
    mz = 0.0
    rotor_momentum_z = 0.0
    jr = params[P_ROTOR_INERTIA]
    k_drag = params[P_ROTOR_DRAG]
    for i in range(ROTORS):
        w = x[X_ROTOR_SPEED + i]
        spin = params[P_SPIN + i]
        sigma = min(1.0, max(0.0, throttle[i]))
        target = 0.0
        if sigma >= params[P_MIN_THROTTLE] and sigma > 0.0:
            target = max(params[P_SPEED_SLOPE] * sigma + params[P_SPEED_OFFSET], 0.0)
            target *= voltage_ratio * math.sqrt(max(params[P_HEALTH + i], 0.0))
        w_dot = (target - w) / params[P_MOTOR_TAU]
        xdot[X_ROTOR_SPEED + i] = w_dot
        xdot[X_ROTOR_ANGLE + i] = w
        thrust = ct * w * w
        torque = cq * w * w
        aux[A_THRUST + i] = thrust
        aux[A_TORQUE + i] = torque
        # Thrust along -z FRD plus induced drag against the in-plane air velocity.
        rfx = -k_drag * w * vb0
        rfy = -k_drag * w * vb1
        rfz = -thrust
        px = params[P_ROTOR_POS + 3 * i]
        py = params[P_ROTOR_POS + 3 * i + 1]
        pz = params[P_ROTOR_POS + 3 * i + 2]
        fx += rfx
        fy += rfy
        fz += rfz
        mx += py * rfz - pz * rfy
        my += pz * rfx - px * rfz
        # Reaction of the motor torque (drag + spin-up) on the body: a CCW rotor (spin +1)
        # turns the body CW seen from above, i.e. +z in FRD (PX4 ActuatorEffectivenessRotors:
        # moment = ct·(r × axis) - ct·km·axis with axis (0,0,-1), km > 0 for CCW).
        mz += px * rfy - py * rfx + spin * (torque + jr * w_dot)
        # Rotor angular momentum: a CCW rotor spins about -z FRD.
        rotor_momentum_z -= spin * jr * w

    p_ = x[X_RATE]
    q_ = x[X_RATE + 1]
    r_ = x[X_RATE + 2]
    mx -= params[P_ANGULAR_DRAG] * abs(p_) * p_
    my -= params[P_ANGULAR_DRAG + 1] * abs(q_) * q_
    mz -= params[P_ANGULAR_DRAG + 2] * abs(r_) * r_
    aux[A_FORCE_FRD] = fx
    aux[A_FORCE_FRD + 1] = fy
    aux[A_FORCE_FRD + 2] = fz
    aux[A_MOMENT_FRD] = mx
    aux[A_MOMENT_FRD + 1] = my
    aux[A_MOMENT_FRD + 2] = mz
    aux[A_VOLTAGE] = voltage
    aux[A_CURRENT] = current
    aux[A_AIR_DENSITY] = rho
    xdot[X_CHARGE_USED] = current

    # Rigid body: I·ω̇ = M - ω × (I·ω + h_rotors).
    inertia = params[P_INERTIA : P_INERTIA + 9]
    hx = inertia[0] * p_ + inertia[1] * q_ + inertia[2] * r_
    hy = inertia[3] * p_ + inertia[4] * q_ + inertia[5] * r_
    hz = inertia[6] * p_ + inertia[7] * q_ + inertia[8] * r_ + rotor_momentum_z
    tx = mx - (q_ * hz - r_ * hy)
    ty = my - (r_ * hx - p_ * hz)
    tz = mz - (p_ * hy - q_ * hx)
    inv = params[P_INERTIA_INV : P_INERTIA_INV + 9]
    mass = params[P_MASS]
    if mount == MOUNT_FREE:
        xdot[X_RATE] = inv[0] * tx + inv[1] * ty + inv[2] * tz
        xdot[X_RATE + 1] = inv[3] * tx + inv[4] * ty + inv[5] * tz
        xdot[X_RATE + 2] = inv[6] * tx + inv[7] * ty + inv[8] * tz
        an = (r00 * fx + r01 * fy + r02 * fz) / mass
        ae = (r10 * fx + r11 * fy + r12 * fz) / mass
        ad = (r20 * fx + r21 * fy + r22 * fz) / mass + STANDARD_GRAVITY_MPS2
    else:
        # Benches hold the centre of mass still. A gimbal leaves one body axis free; about
        # a fixed principal-frame axis e the motion is I_ee·ω̇ = e·M (gyroscopic terms of a
        # rotation about e itself have no e component).
        xdot[X_RATE] = 0.0
        xdot[X_RATE + 1] = 0.0
        xdot[X_RATE + 2] = 0.0
        if mount == MOUNT_GIMBAL_PITCH:
            xdot[X_RATE + 1] = ty / inertia[4]
        elif mount == MOUNT_GIMBAL_ROLL:
            xdot[X_RATE] = tx / inertia[0]
        an = 0.0
        ae = 0.0
        ad = 0.0
    xdot[X_POS] = x[X_VEL]
    xdot[X_POS + 1] = x[X_VEL + 1]
    xdot[X_POS + 2] = x[X_VEL + 2]
    xdot[X_VEL] = an
    xdot[X_VEL + 1] = ae
    xdot[X_VEL + 2] = ad
    aux[A_ACCEL_NED] = an
    aux[A_ACCEL_NED + 1] = ae
    aux[A_ACCEL_NED + 2] = ad
    # q̇ = ½ q ⊗ (0, ω)
    xdot[X_QUAT] = 0.5 * (-q1 * p_ - q2 * q_ - q3 * r_)
    xdot[X_QUAT + 1] = 0.5 * (q0 * p_ + q2 * r_ - q3 * q_)
    xdot[X_QUAT + 2] = 0.5 * (q0 * q_ - q1 * r_ + q3 * p_)
    xdot[X_QUAT + 3] = 0.5 * (q0 * r_ + q1 * q_ - q2 * p_)


@njit(cache=True)
def _specific_force(x, aux):
    """Specific force in FRD, f = Rᵀ·(a - g): (0, 0, -g) when level and held still."""
    q = X_QUAT
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _dcm_entries(x[q], x[q + 1], x[q + 2], x[q + 3])
    an = aux[A_ACCEL_NED]
    ae = aux[A_ACCEL_NED + 1]
    ad = aux[A_ACCEL_NED + 2] - STANDARD_GRAVITY_MPS2
    aux[A_SPECIFIC_FORCE] = r00 * an + r10 * ae + r20 * ad
    aux[A_SPECIFIC_FORCE + 1] = r01 * an + r11 * ae + r21 * ad
    aux[A_SPECIFIC_FORCE + 2] = r02 * an + r12 * ae + r22 * ad


@njit(cache=True)
def _rk4_step(x, params, throttle, wind_ned, dt, k1, k2, k3, k4, xt, aux):
    derivative(x, params, throttle, wind_ned, k1, aux)
    for j in range(X_DYN):
        xt[j] = x[j] + 0.5 * dt * k1[j]
    derivative(xt, params, throttle, wind_ned, k2, aux)
    for j in range(X_DYN):
        xt[j] = x[j] + 0.5 * dt * k2[j]
    derivative(xt, params, throttle, wind_ned, k3, aux)
    for j in range(X_DYN):
        xt[j] = x[j] + dt * k3[j]
    derivative(xt, params, throttle, wind_ned, k4, aux)
    for j in range(X_DYN):
        x[j] += dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
    norm = math.sqrt(x[X_QUAT] ** 2 + x[X_QUAT + 1] ** 2 + x[X_QUAT + 2] ** 2 + x[X_QUAT + 3] ** 2)
    for j in range(4):
        x[X_QUAT + j] /= norm
    for i in range(ROTORS):
        x[X_ROTOR_SPEED + i] = max(x[X_ROTOR_SPEED + i], 0.0)
        x[X_ROTOR_ANGLE + i] = x[X_ROTOR_ANGLE + i] % (2.0 * math.pi)


@njit(cache=True)
def _ground_contact(x):
    """The ground plane z = 0 (home): no sinking, no bounce, no sliding while resting.

    Landing gear and friction are taken as rigid: a vehicle that reaches the ground stops
    there (inelastic contact), and while its thrust cannot lift it, it stays put on its
    legs with the attitude it landed with.
    """
    if x[X_POS + 2] >= 0.0:
        x[X_POS + 2] = 0.0
        x[X_VEL] = 0.0
        x[X_VEL + 1] = 0.0
        x[X_VEL + 2] = min(x[X_VEL + 2], 0.0)
        x[X_RATE] = 0.0
        x[X_RATE + 1] = 0.0
        x[X_RATE + 2] = 0.0
        x[X_ON_GROUND] = 1.0
    else:
        x[X_ON_GROUND] = 0.0


@njit(cache=True)
def _turbulence_step(x, params, noise, dt, wind_ned):
    """Advance the Dryden shaping filters one step (Euler-Maruyama) and set the wind.

    Low-altitude MIL-F-8785C: σ_w = 0.1·W20, σ_u = σ_v = σ_w/(0.177 + 0.000823h)^0.4,
    L_w = h, L_u = L_v = h/(0.177 + 0.000823h)^1.2 (h in ft, 10-1000 ft). u runs along the
    mean wind, v across it, w down. Filters are scaled so each output has variance σ².
    """
    steady_n = params[P_WIND_STEADY]
    steady_e = params[P_WIND_STEADY + 1]
    wind_ned[0] = steady_n
    wind_ned[1] = steady_e
    wind_ned[2] = params[P_WIND_STEADY + 2]
    w20 = params[P_W20]
    if w20 <= 0.0:
        return
    h_ft = min(max(-x[X_POS + 2] / _FT, 10.0), 1000.0)
    factor = 0.177 + 0.000823 * h_ft
    sigma_w = 0.1 * w20
    sigma_uv = sigma_w / factor**0.4
    length_uv = h_ft / factor**1.2 * _FT
    length_w = h_ft * _FT
    airspeed = math.sqrt(
        (x[X_VEL] - steady_n) ** 2 + (x[X_VEL + 1] - steady_e) ** 2 + x[X_VEL + 2] ** 2
    )
    airspeed = max(airspeed, DRYDEN_MIN_AIRSPEED_MPS)
    tau_uv = length_uv / airspeed
    tau_w = length_w / airspeed
    sqrt_dt = math.sqrt(dt)
    t = X_TURBULENCE
    # u: first-order, ż = (-z + n)/τ, y = σ·√(2τ)·z has variance σ².
    x[t] += (-x[t] * dt + noise[0] * sqrt_dt) / tau_uv
    u = sigma_uv * math.sqrt(2.0 * tau_uv) * x[t]
    # v, w: (1 + √3τs)/(1 + τs)², y = σ·√τ·(z1 + √3·τ·z2) has variance σ².
    v = 0.0
    w = 0.0
    for k in range(2):
        tau = tau_uv if k == 0 else tau_w
        sigma = sigma_uv if k == 0 else sigma_w
        i1 = t + 1 + 2 * k
        z1 = x[i1]
        z2 = x[i1 + 1]
        x[i1] = z1 + z2 * dt
        x[i1 + 1] = z2 + (-(z1 + 2.0 * tau * z2) * dt + noise[1 + k] * sqrt_dt) / (tau * tau)
        y = sigma * math.sqrt(tau) * (z1 + _SQRT3 * tau * z2)
        if k == 0:
            v = y
        else:
            w = y
    horizontal = math.hypot(steady_n, steady_e)
    cos_h = steady_n / horizontal if horizontal > 0.0 else 1.0
    sin_h = steady_e / horizontal if horizontal > 0.0 else 0.0
    wind_ned[0] += u * cos_h - v * sin_h
    wind_ned[1] += u * sin_h + v * cos_h
    wind_ned[2] += w


@njit(cache=True)
def _advance_one(x, aux, params, throttle, noise, n_steps, dt):
    k1 = np.empty(X_DYN)
    k2 = np.empty(X_DYN)
    k3 = np.empty(X_DYN)
    k4 = np.empty(X_DYN)
    xt = np.empty(X_DYN)
    wind = np.empty(3)
    zero_noise = np.zeros(3)
    free = int(params[P_MOUNT]) == MOUNT_FREE
    for step in range(n_steps):
        _turbulence_step(x, params, noise[step] if noise.shape[0] > 0 else zero_noise, dt, wind)
        _rk4_step(x, params, throttle, wind, dt, k1, k2, k3, k4, xt, aux)
        if free:
            _ground_contact(x)
    # Outputs at the final state.
    _turbulence_step(x, params, zero_noise, 0.0, wind)
    derivative(x, params, throttle, wind, k1, aux)
    if x[X_ON_GROUND] > 0.0:
        aux[A_ACCEL_NED] = 0.0
        aux[A_ACCEL_NED + 1] = 0.0
        aux[A_ACCEL_NED + 2] = 0.0
    for j in range(3):
        aux[A_WIND_NED + j] = wind[j]
    _specific_force(x, aux)


@njit(cache=True)
def advance_serial(states, aux, params, throttles, noise, n_steps, dt):
    """Advance each vehicle ``n_steps`` substeps of ``dt`` with constant throttles.

    Returns False, without touching any state, when a throttle is not finite.
    """
    if not np.all(np.isfinite(throttles)):
        return False
    for k in range(states.shape[0]):
        _advance_one(states[k], aux[k], params[k], throttles[k], noise[k], n_steps, dt)
    return True


@njit(cache=True, parallel=True)
def advance_parallel(states, aux, params, throttles, noise, n_steps, dt):
    """:func:`advance_serial` with vehicles spread over the CPU cores (large batches)."""
    if not np.all(np.isfinite(throttles)):
        return False
    for k in prange(states.shape[0]):
        _advance_one(states[k], aux[k], params[k], throttles[k], noise[k], n_steps, dt)
    return True
