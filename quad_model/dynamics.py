"""The compiled 5 kHz core: a pure derivative, an RK4 substep, and the substep loop.

Why compiled: a 6-DOF step with motors, battery and wind in numpy costs 30-100 µs, while
100× real time at 5 kHz leaves 2 µs. numba compiles the loop so one ``advance()`` is one
call into machine code (``cache=True`` keeps compiled code between runs).

Why flat arrays: numba dispatches a call with a few float64 arrays in well under a
microsecond, whereas a record of twenty named arrays costs several. The layouts below name
every slot once; :mod:`quad_model.model` wraps them in named fields for users.

Why vehicles innermost: QuadBatch steps thousands of vehicles, and one vehicle's step is a
long chain of dependent operations. With every array [slot, vehicle] and the loop over
vehicles innermost, LLVM runs LANES vehicles per SIMD instruction. A lone vehicle
(QuadModel is a batch of one) runs the same loops' scalar remainder: the same code, and,
without fastmath, the same numbers bit for bit.

Where a vehicle-step goes (measured, one core, a chunk of 8): four derivative evaluations
of about 20 ns each (some 500 AVX-512 instructions per 8 lanes, 14 of them divisions, plus
the overlap checks LLVM runs before each loop), the ISA pressure's pow (a scalar libm call
per vehicle, about 18 ns) and the RK4 stage updates (about 15 ns): 150-180 ns. The issue's
goal, 10,000 vehicle-s/s on two cores, needs 40 ns: fewer operations per derivative (the
parameter divisions as products, a vectorizable pow) and one fused loop per substep are
what remains, and each changes the numbers in the last bits.

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

# Inputs held over one substep: the ESC throttles and the air the vehicle flies in.
_u = _Layout()
U_THROTTLE = _u.add(ROTORS)  # 0..1, clamped in the derivative as an ESC does
U_WIND = _u.add(3)  # NED, m/s: steady + turbulence
U_AIR_DENSITY = _u.add(1)  # kg/m³
U_SIZE = _u.size

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
P_SPEED_SCALE = _p.add(ROTORS)  # √ of the thrust fraction each motor-propeller unit delivers
P_HOME_ALT = _p.add(1)
P_WIND_STEADY = _p.add(3)
P_W20 = _p.add(1)
P_TEMP_OFFSET = _p.add(1)
P_SIZE = _p.size

# Dryden (MIL-F-8785C) needs a speed through the air mass; hovering in calm air it would be
# zero, so the correlation time uses at least this speed.
DRYDEN_MIN_AIRSPEED_MPS = 1.0
_FT = 0.3048
_SQRT3 = math.sqrt(3.0)
_TWO_PI = 2.0 * math.pi
_PER_TURN = 1.0 / _TWO_PI


#: Vehicles per chunk: the SIMD width (8 doubles in an AVX-512 register). A chunk runs a
#: whole advance() on a scratch copy (about 15 kB) that stays in the L1 cache; 16 or 32
#: lanes measured no faster.
LANES = 8

# Scratch rows of one chunk (QuadBatch keeps one block per chunk, so no call allocates).
_w = _Layout()
W_STATE = _w.add(X_SIZE)
W_STAGE = _w.add(X_DYN)  # the state an RK4 stage evaluates the derivative at
W_K = _w.add(4 * X_DYN)  # the four RK4 slopes
W_INPUT = _w.add(U_SIZE)
W_OUTPUT = _w.add(A_SIZE)
W_PARAMS = _w.add(P_SIZE)
W_SIZE = _w.size

# The kernels below index a chunk's scratch as [slot·LANES + lane] and loop over lanes
# innermost. No fastmath: lane k computes exactly what a lone vehicle computes, in any
# chunk, on any core. error_model="numpy" drops the division-by-zero checks that would keep
# the loops scalar. Helpers that take a lane ``v`` are plain calls, which LLVM inlines
# before it vectorizes; numba's inline="always" would leave array reference counting in
# the loop, which keeps it scalar.
_kernel = njit(cache=True, error_model="numpy")


def lane_block(row: np.ndarray) -> np.ndarray:
    """One vehicle's slots (a state, parameter or output row) as a scratch block, every lane
    the same: how Python calls a lane helper (e.g. ``battery_terminal(block, 0, ...)``)."""
    return np.repeat(np.asarray(row, dtype=float), LANES)


@_kernel
def air_density_kgpm3(p: np.ndarray, v: int, down_m: float) -> float:
    """Air density at a NED height: ISA pressure with the day's temperature offset."""
    altitude = p[P_HOME_ALT * LANES + v] - down_m
    temperature = _env.isa_temperature_k(altitude) + p[P_TEMP_OFFSET * LANES + v]
    return _env.isa_pressure_pa(altitude) / (_DRY_AIR_R * temperature)


@_kernel
def open_circuit_voltage(p: np.ndarray, v: int, charge_used_c: float) -> float:
    """The pack's EMF: each cell linear in state of charge, full to empty (PX4's model).

    :func:`quad_model.model.charge_used_for_voltage_c` is its inverse.
    """
    soc = min(1.0, max(0.0, 1.0 - charge_used_c / p[P_CAPACITY_C * LANES + v]))
    cell = (
        p[P_CELL_EMPTY * LANES + v]
        + (p[P_CELL_FULL * LANES + v] - p[P_CELL_EMPTY * LANES + v]) * soc
    )
    return p[P_CELLS * LANES + v] * cell


@_kernel
def battery_terminal(p: np.ndarray, v: int, charge_used_c: float, load_w: float) -> tuple:
    """Terminal voltage and current of the pack delivering ``load_w``.

    V = E - R·I with I = P/V gives V² - E·V + R·P = 0; the upper root is the operating
    point. Past the pack's maximum power (E²/4R) the voltage collapses to E/2.
    """
    emf = open_circuit_voltage(p, v, charge_used_c)
    disc = emf * emf - 4.0 * p[P_R_INTERNAL * LANES + v] * load_w
    voltage = 0.5 * (emf + math.sqrt(max(disc, 0.0)))
    return voltage, load_w / voltage


@_kernel
def _add_rotor(x, p, u, xdot, aux, v, i, ct, cq, voltage_ratio, vb0, vb1, fm):
    """Rotor ``i`` of lane ``v``: its spin-up into ``xdot``, thrust and torque into ``aux``,
    and its force, moment and angular momentum added to ``fm`` = (f FRD, M FRD, h_z)."""
    fx, fy, fz, mx, my, mz, rotor_momentum_z = fm
    w = x[(X_ROTOR_SPEED + i) * LANES + v]
    spin = p[(P_SPIN + i) * LANES + v]
    jr = p[P_ROTOR_INERTIA * LANES + v]
    sigma = min(1.0, max(0.0, u[(U_THROTTLE + i) * LANES + v]))
    target = 0.0
    if sigma >= p[P_MIN_THROTTLE * LANES + v] and sigma > 0.0:
        target = max(p[P_SPEED_SLOPE * LANES + v] * sigma + p[P_SPEED_OFFSET * LANES + v], 0.0)
        target *= voltage_ratio * p[(P_SPEED_SCALE + i) * LANES + v]
    w_dot = (target - w) / p[P_MOTOR_TAU * LANES + v]
    xdot[(X_ROTOR_SPEED + i) * LANES + v] = w_dot
    xdot[(X_ROTOR_ANGLE + i) * LANES + v] = w
    thrust = ct * w * w
    torque = cq * w * w
    aux[(A_THRUST + i) * LANES + v] = thrust
    aux[(A_TORQUE + i) * LANES + v] = torque
    # Thrust along -z FRD plus induced drag against the in-plane air velocity.
    k_drag = p[P_ROTOR_DRAG * LANES + v]
    rfx = -k_drag * w * vb0
    rfy = -k_drag * w * vb1
    rfz = -thrust
    px = p[(P_ROTOR_POS + 3 * i) * LANES + v]
    py = p[(P_ROTOR_POS + 3 * i + 1) * LANES + v]
    pz = p[(P_ROTOR_POS + 3 * i + 2) * LANES + v]
    # Reaction of the motor torque (drag + spin-up) on the body: a CCW rotor (spin +1) turns
    # the body CW seen from above, i.e. +z in FRD (PX4 ActuatorEffectivenessRotors: moment =
    # ct·(r × axis) - ct·km·axis with axis (0,0,-1), km > 0 for CCW). Its angular momentum:
    # a CCW rotor spins about -z FRD.
    return (
        fx + rfx,
        fy + rfy,
        fz + rfz,
        mx + (py * rfz - pz * rfy),
        my + (pz * rfx - px * rfz),
        mz + (px * rfy - py * rfx + spin * (torque + jr * w_dot)),
        rotor_momentum_z - spin * jr * w,
    )


@_kernel
def derivative(
    x: np.ndarray,
    p: np.ndarray,
    u: np.ndarray,
    xdot: np.ndarray,
    aux: np.ndarray,
    mount: int,
    lanes: int,
) -> None:
    """Time derivative of the integrated state ``x[:X_DYN]`` of lanes ``0..lanes-1``.

    Pure: reads only its inputs (state ``x``, parameters ``p``, held inputs ``u``). Writes
    ``xdot[:X_DYN]`` and, as a by-product, the outputs in ``aux``. Every array is a chunk's
    scratch block, indexed [slot·LANES + lane].
    """
    for v in range(lanes):
        q0, q1, q2, q3 = (
            x[X_QUAT * LANES + v],
            x[(X_QUAT + 1) * LANES + v],
            x[(X_QUAT + 2) * LANES + v],
            x[(X_QUAT + 3) * LANES + v],
        )
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = _dcm_entries(q0, q1, q2, q3)
        rho = u[U_AIR_DENSITY * LANES + v]
        density_ratio = rho / p[P_RHO_REF * LANES + v]

        # Propulsion: shaft power sets the battery load, the battery voltage sets motor speed.
        ct = p[P_CT * LANES + v] * density_ratio
        cq = p[P_CQ * LANES + v] * density_ratio
        w0, w1 = x[X_ROTOR_SPEED * LANES + v], x[(X_ROTOR_SPEED + 1) * LANES + v]
        w2, w3 = x[(X_ROTOR_SPEED + 2) * LANES + v], x[(X_ROTOR_SPEED + 3) * LANES + v]
        shaft_w = cq * w0 * w0 * w0 + cq * w1 * w1 * w1 + cq * w2 * w2 * w2 + cq * w3 * w3 * w3
        load_w = shaft_w / p[P_EFFICIENCY * LANES + v] + p[P_AVIONICS_W * LANES + v]
        voltage, current = battery_terminal(p, v, x[X_CHARGE_USED * LANES + v], load_w)
        voltage_ratio = voltage / p[P_CURVE_VOLTAGE * LANES + v]

        # Air-relative velocity in the body frame.
        va_n = x[X_VEL * LANES + v] - u[U_WIND * LANES + v]
        va_e = x[(X_VEL + 1) * LANES + v] - u[(U_WIND + 1) * LANES + v]
        va_d = x[(X_VEL + 2) * LANES + v] - u[(U_WIND + 2) * LANES + v]
        vb0 = r00 * va_n + r10 * va_e + r20 * va_d
        vb1 = r01 * va_n + r11 * va_e + r21 * va_d
        vb2 = r02 * va_n + r12 * va_e + r22 * va_d

        # Body drag, quadratic per axis, then each rotor's force and moment.
        half_rho = 0.5 * rho
        fm = (
            -half_rho * p[P_DRAG_AREA * LANES + v] * abs(vb0) * vb0,
            -half_rho * p[(P_DRAG_AREA + 1) * LANES + v] * abs(vb1) * vb1,
            -half_rho * p[(P_DRAG_AREA + 2) * LANES + v] * abs(vb2) * vb2,
            0.0,
            0.0,
            0.0,
            0.0,
        )
        # Written out rotor by rotor: a loop here would be the innermost one, and LLVM
        # vectorizes only innermost loops (the lanes' loop is the one to vectorize).
        fm = _add_rotor(x, p, u, xdot, aux, v, 0, ct, cq, voltage_ratio, vb0, vb1, fm)
        fm = _add_rotor(x, p, u, xdot, aux, v, 1, ct, cq, voltage_ratio, vb0, vb1, fm)
        fm = _add_rotor(x, p, u, xdot, aux, v, 2, ct, cq, voltage_ratio, vb0, vb1, fm)
        fm = _add_rotor(x, p, u, xdot, aux, v, 3, ct, cq, voltage_ratio, vb0, vb1, fm)
        fx, fy, fz, mx, my, mz, rotor_momentum_z = fm

        p_ = x[X_RATE * LANES + v]
        q_ = x[(X_RATE + 1) * LANES + v]
        r_ = x[(X_RATE + 2) * LANES + v]
        mx -= p[P_ANGULAR_DRAG * LANES + v] * abs(p_) * p_
        my -= p[(P_ANGULAR_DRAG + 1) * LANES + v] * abs(q_) * q_
        mz -= p[(P_ANGULAR_DRAG + 2) * LANES + v] * abs(r_) * r_
        aux[A_FORCE_FRD * LANES + v] = fx
        aux[(A_FORCE_FRD + 1) * LANES + v] = fy
        aux[(A_FORCE_FRD + 2) * LANES + v] = fz
        aux[A_MOMENT_FRD * LANES + v] = mx
        aux[(A_MOMENT_FRD + 1) * LANES + v] = my
        aux[(A_MOMENT_FRD + 2) * LANES + v] = mz
        aux[A_VOLTAGE * LANES + v] = voltage
        aux[A_CURRENT * LANES + v] = current
        aux[A_AIR_DENSITY * LANES + v] = rho
        xdot[X_CHARGE_USED * LANES + v] = current

        # Rigid body: I·ω̇ = M - ω × (I·ω + h_rotors).
        i_ = P_INERTIA
        hx = p[i_ * LANES + v] * p_ + p[(i_ + 1) * LANES + v] * q_ + p[(i_ + 2) * LANES + v] * r_
        hy = (
            p[(i_ + 3) * LANES + v] * p_
            + p[(i_ + 4) * LANES + v] * q_
            + p[(i_ + 5) * LANES + v] * r_
        )
        hz = (
            p[(i_ + 6) * LANES + v] * p_
            + p[(i_ + 7) * LANES + v] * q_
            + p[(i_ + 8) * LANES + v] * r_
            + rotor_momentum_z
        )
        tx = mx - (q_ * hz - r_ * hy)
        ty = my - (r_ * hx - p_ * hz)
        tz = mz - (p_ * hy - q_ * hx)
        n_ = P_INERTIA_INV
        mass = p[P_MASS * LANES + v]
        if mount == MOUNT_FREE:
            xdot[X_RATE * LANES + v] = (
                p[n_ * LANES + v] * tx + p[(n_ + 1) * LANES + v] * ty + p[(n_ + 2) * LANES + v] * tz
            )
            xdot[(X_RATE + 1) * LANES + v] = (
                p[(n_ + 3) * LANES + v] * tx
                + p[(n_ + 4) * LANES + v] * ty
                + p[(n_ + 5) * LANES + v] * tz
            )
            xdot[(X_RATE + 2) * LANES + v] = (
                p[(n_ + 6) * LANES + v] * tx
                + p[(n_ + 7) * LANES + v] * ty
                + p[(n_ + 8) * LANES + v] * tz
            )
            an = (r00 * fx + r01 * fy + r02 * fz) / mass
            ae = (r10 * fx + r11 * fy + r12 * fz) / mass
            ad = (r20 * fx + r21 * fy + r22 * fz) / mass + STANDARD_GRAVITY_MPS2
        else:
            # Benches hold the centre of mass still. A gimbal leaves one body axis free;
            # about a fixed principal-frame axis e the motion is I_ee·ω̇ = e·M (gyroscopic
            # terms of a rotation about e itself have no e component).
            xdot[X_RATE * LANES + v] = 0.0
            xdot[(X_RATE + 1) * LANES + v] = 0.0
            xdot[(X_RATE + 2) * LANES + v] = 0.0
            if mount == MOUNT_GIMBAL_PITCH:
                xdot[(X_RATE + 1) * LANES + v] = ty / p[(i_ + 4) * LANES + v]
            elif mount == MOUNT_GIMBAL_ROLL:
                xdot[X_RATE * LANES + v] = tx / p[i_ * LANES + v]
            an = 0.0
            ae = 0.0
            ad = 0.0
        xdot[X_POS * LANES + v] = x[X_VEL * LANES + v]
        xdot[(X_POS + 1) * LANES + v] = x[(X_VEL + 1) * LANES + v]
        xdot[(X_POS + 2) * LANES + v] = x[(X_VEL + 2) * LANES + v]
        xdot[X_VEL * LANES + v] = an
        xdot[(X_VEL + 1) * LANES + v] = ae
        xdot[(X_VEL + 2) * LANES + v] = ad
        aux[A_ACCEL_NED * LANES + v] = an
        aux[(A_ACCEL_NED + 1) * LANES + v] = ae
        aux[(A_ACCEL_NED + 2) * LANES + v] = ad
        # q̇ = ½ q ⊗ (0, ω)
        xdot[X_QUAT * LANES + v] = 0.5 * (-q1 * p_ - q2 * q_ - q3 * r_)
        xdot[(X_QUAT + 1) * LANES + v] = 0.5 * (q0 * p_ + q2 * r_ - q3 * q_)
        xdot[(X_QUAT + 2) * LANES + v] = 0.5 * (q0 * q_ - q1 * r_ + q3 * p_)
        xdot[(X_QUAT + 3) * LANES + v] = 0.5 * (q0 * r_ + q1 * q_ - q2 * p_)


@_kernel
def _dryden(x, p, u, v, n0, n1, n2, dt):
    """Advance lane ``v``'s Dryden shaping filters one step (Euler-Maruyama), add the gust.

    Low-altitude MIL-F-8785C: σ_w = 0.1·W20, σ_u = σ_v = σ_w/(0.177 + 0.000823h)^0.4,
    L_w = h, L_u = L_v = h/(0.177 + 0.000823h)^1.2 (h in ft, 10-1000 ft). u runs along the
    mean wind, v across it, w down. Filters are scaled so each output has variance σ².
    ``n0..n2`` are standard normal draws (zero with ``dt`` = 0: the gust of the state now).
    """
    w20 = p[P_W20 * LANES + v]
    if w20 > 0.0:
        steady_n = p[P_WIND_STEADY * LANES + v]
        steady_e = p[(P_WIND_STEADY + 1) * LANES + v]
        h_ft = min(max(-x[(X_POS + 2) * LANES + v] / _FT, 10.0), 1000.0)
        factor = 0.177 + 0.000823 * h_ft
        sigma_w = 0.1 * w20
        sigma_uv = sigma_w / factor**0.4
        length_uv = h_ft / factor**1.2 * _FT
        length_w = h_ft * _FT
        airspeed = math.sqrt(
            (x[X_VEL * LANES + v] - steady_n) ** 2
            + (x[(X_VEL + 1) * LANES + v] - steady_e) ** 2
            + x[(X_VEL + 2) * LANES + v] ** 2
        )
        airspeed = max(airspeed, DRYDEN_MIN_AIRSPEED_MPS)
        tau_uv = length_uv / airspeed
        tau_w = length_w / airspeed
        sqrt_dt = math.sqrt(dt)
        t = X_TURBULENCE
        # u: first-order, ż = (-z + n)/τ, y = σ·√(2τ)·z has variance σ².
        x[t * LANES + v] += (-x[t * LANES + v] * dt + n0 * sqrt_dt) / tau_uv
        gust_u = sigma_uv * math.sqrt(2.0 * tau_uv) * x[t * LANES + v]
        # v, w: (1 + √3τs)/(1 + τs)², y = σ·√τ·(z1 + √3·τ·z2) has variance σ².
        z1 = x[(t + 1) * LANES + v]
        z2 = x[(t + 2) * LANES + v]
        x[(t + 1) * LANES + v] = z1 + z2 * dt
        x[(t + 2) * LANES + v] = z2 + (-(z1 + 2.0 * tau_uv * z2) * dt + n1 * sqrt_dt) / (
            tau_uv * tau_uv
        )
        gust_v = sigma_uv * math.sqrt(tau_uv) * (z1 + _SQRT3 * tau_uv * z2)
        z1 = x[(t + 3) * LANES + v]
        z2 = x[(t + 4) * LANES + v]
        x[(t + 3) * LANES + v] = z1 + z2 * dt
        x[(t + 4) * LANES + v] = z2 + (-(z1 + 2.0 * tau_w * z2) * dt + n2 * sqrt_dt) / (
            tau_w * tau_w
        )
        gust_w = sigma_w * math.sqrt(tau_w) * (z1 + _SQRT3 * tau_w * z2)
        horizontal = math.hypot(steady_n, steady_e)
        cos_h = steady_n / horizontal if horizontal > 0.0 else 1.0
        sin_h = steady_e / horizontal if horizontal > 0.0 else 0.0
        u[U_WIND * LANES + v] += gust_u * cos_h - gust_v * sin_h
        u[(U_WIND + 1) * LANES + v] += gust_u * sin_h + gust_v * cos_h
        u[(U_WIND + 2) * LANES + v] += gust_w


@_kernel
def _air(x, p, u, noise, first, step, dt, lanes):
    """The air each lane flies through for the next substep: wind and density.

    Like the throttles, both are held over the substep's four derivative evaluations
    (the altitude moves < 1 mm in 0.2 ms: a density change below 1e-7). Turbulence draws
    ``noise[first + lane, step]``; ``dt`` = 0 gives the wind of the state now.
    """
    turbulent = False
    for v in range(lanes):
        u[U_WIND * LANES + v] = p[P_WIND_STEADY * LANES + v]
        u[(U_WIND + 1) * LANES + v] = p[(P_WIND_STEADY + 1) * LANES + v]
        u[(U_WIND + 2) * LANES + v] = p[(P_WIND_STEADY + 2) * LANES + v]
        u[U_AIR_DENSITY * LANES + v] = air_density_kgpm3(p, v, x[(X_POS + 2) * LANES + v])
        turbulent |= p[P_W20 * LANES + v] > 0.0
    if not turbulent:  # the pow calls of the filters only where there is turbulence
        return
    if dt > 0.0:
        for v in range(lanes):
            k = first + v
            _dryden(x, p, u, v, noise[k, step, 0], noise[k, step, 1], noise[k, step, 2], dt)
    else:
        for v in range(lanes):
            _dryden(x, p, u, v, 0.0, 0.0, 0.0, 0.0)


@_kernel
def _stage(x, k, h, xt, lanes):
    """The state an RK4 stage evaluates at: ``xt = x + h·k``."""
    for j in range(X_DYN):
        for v in range(lanes):
            i = j * LANES + v
            xt[i] = x[i] + h * k[i]


@_kernel
def _rk4_step(x, p, u, xt, k, aux, mount, dt, lanes):
    """One classic RK4 substep of every lane, then the quaternion renormalized, rotor speeds
    kept >= 0 and rotor angles wrapped."""
    n = X_DYN * LANES
    k1, k2, k3, k4 = k[:n], k[n : 2 * n], k[2 * n : 3 * n], k[3 * n :]
    derivative(x, p, u, k1, aux, mount, lanes)
    _stage(x, k1, 0.5 * dt, xt, lanes)
    derivative(xt, p, u, k2, aux, mount, lanes)
    _stage(x, k2, 0.5 * dt, xt, lanes)
    derivative(xt, p, u, k3, aux, mount, lanes)
    _stage(x, k3, dt, xt, lanes)
    derivative(xt, p, u, k4, aux, mount, lanes)
    for j in range(X_DYN):
        for v in range(lanes):
            i = j * LANES + v
            x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    for v in range(lanes):
        q = X_QUAT
        norm = math.sqrt(
            x[q * LANES + v] * x[q * LANES + v]
            + x[(q + 1) * LANES + v] * x[(q + 1) * LANES + v]
            + x[(q + 2) * LANES + v] * x[(q + 2) * LANES + v]
            + x[(q + 3) * LANES + v] * x[(q + 3) * LANES + v]
        )
        for j in range(4):
            x[(q + j) * LANES + v] /= norm
        for i in range(ROTORS):
            x[(X_ROTOR_SPEED + i) * LANES + v] = max(x[(X_ROTOR_SPEED + i) * LANES + v], 0.0)
            # Python's angle % 2π (exactly so for one turn per step: a - 2π is exact there),
            # as arithmetic the vector units have instead of a libm fmod call.
            angle = x[(X_ROTOR_ANGLE + i) * LANES + v]
            x[(X_ROTOR_ANGLE + i) * LANES + v] = angle - _TWO_PI * np.floor(angle * _PER_TURN)


@_kernel
def _ground_contact(x, lanes):
    """The ground plane z = 0 (home): no sinking, no bounce, no sliding while resting.

    Landing gear and friction are taken as rigid: a vehicle that reaches the ground stops
    there (inelastic contact), and while its thrust cannot lift it, it stays put on its
    legs with the attitude it landed with.
    """
    for v in range(lanes):
        if x[(X_POS + 2) * LANES + v] >= 0.0:
            x[(X_POS + 2) * LANES + v] = 0.0
            x[X_VEL * LANES + v] = 0.0
            x[(X_VEL + 1) * LANES + v] = 0.0
            x[(X_VEL + 2) * LANES + v] = min(x[(X_VEL + 2) * LANES + v], 0.0)
            x[X_RATE * LANES + v] = 0.0
            x[(X_RATE + 1) * LANES + v] = 0.0
            x[(X_RATE + 2) * LANES + v] = 0.0
            x[X_ON_GROUND * LANES + v] = 1.0
        else:
            x[X_ON_GROUND * LANES + v] = 0.0


@_kernel
def _outputs(x, aux, u, lanes):
    """Outputs at the final state that the derivative does not give: zero acceleration on
    the ground, the wind, and the specific force f = Rᵀ·(a - g) ((0, 0, -g) level at rest)."""
    for v in range(lanes):
        if x[X_ON_GROUND * LANES + v] > 0.0:
            aux[A_ACCEL_NED * LANES + v] = 0.0
            aux[(A_ACCEL_NED + 1) * LANES + v] = 0.0
            aux[(A_ACCEL_NED + 2) * LANES + v] = 0.0
        aux[A_WIND_NED * LANES + v] = u[U_WIND * LANES + v]
        aux[(A_WIND_NED + 1) * LANES + v] = u[(U_WIND + 1) * LANES + v]
        aux[(A_WIND_NED + 2) * LANES + v] = u[(U_WIND + 2) * LANES + v]
        q = X_QUAT
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = _dcm_entries(
            x[q * LANES + v], x[(q + 1) * LANES + v], x[(q + 2) * LANES + v], x[(q + 3) * LANES + v]
        )
        an = aux[A_ACCEL_NED * LANES + v]
        ae = aux[(A_ACCEL_NED + 1) * LANES + v]
        ad = aux[(A_ACCEL_NED + 2) * LANES + v] - STANDARD_GRAVITY_MPS2
        aux[A_SPECIFIC_FORCE * LANES + v] = r00 * an + r10 * ae + r20 * ad
        aux[(A_SPECIFIC_FORCE + 1) * LANES + v] = r01 * an + r11 * ae + r21 * ad
        aux[(A_SPECIFIC_FORCE + 2) * LANES + v] = r02 * an + r12 * ae + r22 * ad


@_kernel
def _advance_chunk(states, outputs, params, throttles, noise, work, chunk, mount, n_steps, dt):
    """Run vehicles ``chunk·LANES ...`` through ``n_steps`` substeps on the chunk's scratch.

    The scratch is flat, slot-major ([slot·LANES + lane]): with a stride LLVM knows, it
    sees that the slots never overlap and vectorizes without per-slot overlap checks.
    """
    first = chunk * LANES
    lanes = min(LANES, states.shape[1] - first)
    w = work[chunk]
    x = w[W_STATE * LANES : (W_STATE + X_SIZE) * LANES]
    xt = w[W_STAGE * LANES : (W_STAGE + X_DYN) * LANES]
    k = w[W_K * LANES : (W_K + 4 * X_DYN) * LANES]
    u = w[W_INPUT * LANES : (W_INPUT + U_SIZE) * LANES]
    aux = w[W_OUTPUT * LANES : (W_OUTPUT + A_SIZE) * LANES]
    p = w[W_PARAMS * LANES : (W_PARAMS + P_SIZE) * LANES]
    for j in range(X_SIZE):
        for v in range(lanes):
            x[j * LANES + v] = states[j, first + v]
    for j in range(P_SIZE):
        for v in range(lanes):
            p[j * LANES + v] = params[j, first + v]
    for i in range(ROTORS):
        for v in range(lanes):
            u[(U_THROTTLE + i) * LANES + v] = throttles[i, first + v]
    for step in range(n_steps):
        _air(x, p, u, noise, first, step, dt, lanes)
        _rk4_step(x, p, u, xt, k, aux, mount, dt, lanes)
        if mount == MOUNT_FREE:
            _ground_contact(x, lanes)
    # Outputs at the final state.
    _air(x, p, u, noise, first, 0, 0.0, lanes)
    derivative(x, p, u, k, aux, mount, lanes)
    _outputs(x, aux, u, lanes)
    for j in range(X_SIZE):
        for v in range(lanes):
            states[j, first + v] = x[j * LANES + v]
    for j in range(A_SIZE):
        for v in range(lanes):
            outputs[j, first + v] = aux[j * LANES + v]


@_kernel
def _finite(a):
    """Whether every value is finite (a throttle the kernel can hold)."""
    finite = True
    for value in a.flat:
        finite &= math.isfinite(value)
    return finite


@_kernel
def advance_serial(
    states: np.ndarray,
    outputs: np.ndarray,
    params: np.ndarray,
    throttles: np.ndarray,
    noise: np.ndarray,
    work: np.ndarray,
    mount: int,
    n_steps: int,
    dt: float,
) -> bool:
    """Advance each vehicle ``n_steps`` substeps of ``dt`` with constant throttles.

    Arrays are [slot, vehicle] (``noise`` is [vehicle, step, 3], ``work`` one scratch
    block per chunk of LANES vehicles). Returns False, without touching any state, when a
    throttle is not finite.
    """
    if not _finite(throttles):
        return False
    for chunk in range(work.shape[0]):
        _advance_chunk(states, outputs, params, throttles, noise, work, chunk, mount, n_steps, dt)
    return True


@njit(cache=True, error_model="numpy", parallel=True)
def advance_parallel(
    states: np.ndarray,
    outputs: np.ndarray,
    params: np.ndarray,
    throttles: np.ndarray,
    noise: np.ndarray,
    work: np.ndarray,
    mount: int,
    n_steps: int,
    dt: float,
) -> bool:
    """:func:`advance_serial` with chunks spread over the CPU cores (large batches)."""
    if not _finite(throttles):
        return False
    for chunk in prange(work.shape[0]):
        _advance_chunk(states, outputs, params, throttles, noise, work, chunk, mount, n_steps, dt)
    return True
