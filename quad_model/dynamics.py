"""The compiled 5 kHz core: a pure derivative, an RK4 substep, and the substep loop.

Why compiled: a 6-DOF step with motors, battery and wind in numpy costs 30-100 µs, while
100× real time at 5 kHz leaves 2 µs. numba compiles the loop so one ``advance()`` is one
call into machine code (``cache=True`` keeps compiled code between runs).

Why flat arrays: numba dispatches a call with a few float64 arrays in well under a
microsecond, whereas a record of twenty named arrays costs several. The layouts below name
every slot once; :mod:`quad_model.model` wraps them in named fields for users.

Why vehicles innermost: QuadBatch steps thousands of vehicles, and one vehicle's step is a
long chain of dependent operations. With every array [slot, vehicle] and the loop over
vehicles innermost, LLVM runs LANES vehicles per SIMD instruction. A whole chunk runs
loops of a compile-time LANES lanes, straight SIMD code; a lone vehicle (QuadModel is a
batch of one) or a part chunk runs the same source with a run-time count, mostly scalar:
the same IEEE operations and, without fastmath, the same numbers bit for bit.

Where a vehicle-step goes (measured, one core, chunks of 8, 1 ms frames of 5 steps): four
derivative evaluations (some 500 AVX-512 instructions per 8 lanes each; the parameters
they divided by are stored as reciprocals, one division by the battery voltage remains),
the ISA pressure's pow (a scalar libm call per vehicle, about 20 ns), the RK4 stage
updates and the per-call copies in and out of the chunk's scratch: 120-150 ns (185-200
before the single-scratch kernels). The issue's goal, 10,000 vehicle-s/s on two cores,
needs 40 ns: without the pow (air density held constant, measured) a step costs 7 % less,
so what remains is 2.5× fewer operations per derivative, a simpler model or integrator.

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
from quad_model.vehicle import MAX_ROTORS

#: Rotor slots in every layout: a vehicle uses the first ones, a batch's kernel loops over
#: as many as its vehicle with the most rotors has (the throttles' rows).
ROTORS = MAX_ROTORS

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
P_AXIAL_INFLOW = _p.add(1)
P_CELLS = _p.add(1)
P_CAPACITY_C = _p.add(1)
P_CELL_FULL = _p.add(1)
P_CELL_EMPTY = _p.add(1)
P_R_INTERNAL = _p.add(1)
P_EFFICIENCY = _p.add(1)
P_AVIONICS_W = _p.add(1)
P_SPEED_SCALE = _p.add(ROTORS)  # √ of the thrust fraction each motor-propeller unit delivers
P_THRUST_FACTOR = _p.add(ROTORS)  # thrust vs an isolated rotor (coaxial lower: < 1; absent: 0)
P_TORQUE_FACTOR = _p.add(ROTORS)  # drag torque vs an isolated rotor (as the thrust factor)
P_HOME_ALT = _p.add(1)
P_WIND_STEADY = _p.add(3)
P_W20 = _p.add(1)
P_TEMP_OFFSET = _p.add(1)
# Reciprocals of the parameters the derivative divides by: a product costs the vector units
# a fraction of a division (the results differ in the last bit).
P_MASS_INV = _p.add(1)
P_RHO_REF_INV = _p.add(1)
P_MOTOR_TAU_INV = _p.add(1)
P_CURVE_VOLTAGE_INV = _p.add(1)
P_CAPACITY_C_INV = _p.add(1)
P_EFFICIENCY_INV = _p.add(1)
P_SIZE = _p.size

#: The force per unit mass with which legs and ground stop a vehicle that lands or slides
#: (m/s², about 3 g): landing gear takes a touchdown over a few centimetres and a few tenths
#: of a second at most. [estimate]
LANDING_DECELERATION_MPS2 = 30.0
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
W_SLOPE = _w.add(X_DYN)  # that stage's slope
W_SLOPE_SUM = _w.add(X_DYN)  # k1 + 2·k2 + 2·k3 so far
W_INPUT = _w.add(U_SIZE)
W_OUTPUT = _w.add(A_SIZE)
W_VEL_START = _w.add(3)  # the velocity at the start of the advance (ground outputs)
W_PARAMS = _w.add(P_SIZE)
W_SIZE = _w.size

# The kernels below take a chunk's whole scratch ``w`` and index it as [slot·LANES + lane]
# at fixed region offsets (W_*), looping over lanes innermost: one array, so LLVM sees that
# the slots never overlap and needs no overlap checks. No fastmath: lane k computes exactly
# what a lone vehicle computes, in any chunk, on any core. error_model="numpy" drops the
# division-by-zero checks that would keep the loops scalar.
_kernel = njit(cache=True, error_model="numpy")
# The derivative's per-lane helpers are inlined by numba: with a single scratch array as
# argument LLVM's own inliner keeps them as calls, and a call keeps the lane loop scalar.
_inlined = njit(cache=True, error_model="numpy", inline="always")


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
    soc = min(1.0, max(0.0, 1.0 - charge_used_c * p[P_CAPACITY_C_INV * LANES + v]))
    cell = (
        p[P_CELL_EMPTY * LANES + v]
        + (p[P_CELL_FULL * LANES + v] - p[P_CELL_EMPTY * LANES + v]) * soc
    )
    return p[P_CELLS * LANES + v] * cell


@_inlined
def battery_terminal(p: np.ndarray, v: int, charge_used_c: float, load_w: float) -> tuple:
    """Terminal voltage and current of the pack delivering ``load_w``.

    V = E - R·I with I = P/V gives V² - E·V + R·P = 0; the upper root is the operating
    point. Past the pack's maximum power (E²/4R) the voltage collapses to E/2.
    """
    emf = open_circuit_voltage(p, v, charge_used_c)
    disc = emf * emf - 4.0 * p[P_R_INTERNAL * LANES + v] * load_w
    voltage = 0.5 * (emf + math.sqrt(max(disc, 0.0)))
    return voltage, load_w / voltage


#: What :func:`_add_rotor` sums over the rotors: force FRD, moment FRD, angular momentum z.
_ForceMoment = tuple[float, float, float, float, float, float, float]


@_inlined
def _add_rotor(
    w: np.ndarray,
    v: int,
    i: int,
    ct: float,
    cq: float,
    voltage_ratio: float,
    vb0: float,
    vb1: float,
    vb2: float,
    fm: _ForceMoment,
) -> _ForceMoment:
    """Rotor ``i`` of lane ``v`` in :func:`derivative`: its spin-up into the slopes, thrust
    and torque into the outputs, and its force, moment and angular momentum added to ``fm``
    = (f FRD, M FRD, h_z)."""
    xv = W_STAGE * LANES + v
    pv = W_PARAMS * LANES + v
    uv = W_INPUT * LANES + v
    dv = W_SLOPE * LANES + v
    av = W_OUTPUT * LANES + v
    fx, fy, fz, mx, my, mz, rotor_momentum_z = fm
    omega = w[(X_ROTOR_SPEED + i) * LANES + xv]
    spin = w[(P_SPIN + i) * LANES + pv]
    jr = w[P_ROTOR_INERTIA * LANES + pv]
    sigma = min(1.0, max(0.0, w[(U_THROTTLE + i) * LANES + uv]))
    target = 0.0
    if sigma >= w[P_MIN_THROTTLE * LANES + pv] and sigma > 0.0:
        target = max(w[P_SPEED_SLOPE * LANES + pv] * sigma + w[P_SPEED_OFFSET * LANES + pv], 0.0)
        target *= voltage_ratio * w[(P_SPEED_SCALE + i) * LANES + pv]
    w_dot = (target - omega) * w[P_MOTOR_TAU_INV * LANES + pv]
    w[(X_ROTOR_SPEED + i) * LANES + dv] = w_dot
    w[(X_ROTOR_ANGLE + i) * LANES + dv] = omega
    # Thrust along -z FRD, less in a climb (air through the disc from above, vb2 < 0) and
    # more in a descent, plus induced drag against the in-plane air velocity.
    ct_i = ct * w[(P_THRUST_FACTOR + i) * LANES + pv]
    cq_i = cq * w[(P_TORQUE_FACTOR + i) * LANES + pv]
    thrust = ct_i * omega * omega + w[P_AXIAL_INFLOW * LANES + pv] * omega * vb2
    torque = cq_i * omega * omega
    w[(A_THRUST + i) * LANES + av] = thrust
    w[(A_TORQUE + i) * LANES + av] = torque
    k_drag = w[P_ROTOR_DRAG * LANES + pv]
    rfx = -k_drag * omega * vb0
    rfy = -k_drag * omega * vb1
    rfz = -thrust
    px = w[(P_ROTOR_POS + 3 * i) * LANES + pv]
    py = w[(P_ROTOR_POS + 3 * i + 1) * LANES + pv]
    pz = w[(P_ROTOR_POS + 3 * i + 2) * LANES + pv]
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
        rotor_momentum_z - spin * jr * omega,
    )


@_inlined
def _shaft_power(w: np.ndarray, v: int, i: int, cq: float) -> float:
    """Rotor ``i``'s shaft power in lane ``v`` at the stage state."""
    omega = w[(X_ROTOR_SPEED + i) * LANES + W_STAGE * LANES + v]
    return cq * w[(P_TORQUE_FACTOR + i) * LANES + W_PARAMS * LANES + v] * omega * omega * omega


@_kernel
def derivative(w: np.ndarray, mount: int, rotors: int, lanes: int) -> None:
    """Time derivative of lanes ``0..lanes-1`` of a chunk's scratch ``w`` at its RK4 stage
    state (W_STAGE), for vehicles of ``rotors`` rotor slots: writes the slopes (W_SLOPE)
    and, as a by-product, the outputs (W_OUTPUT). Pure: reads only the stage state, the
    parameters and the held inputs.

    Every vehicle has at least four rotors; the slots past them are written out behind
    tests of ``rotors``, which :func:`_substeps_of` passes as a compile-time constant,
    so the tests vanish from the machine code.
    """
    for v in range(lanes):
        xv = W_STAGE * LANES + v
        pv = W_PARAMS * LANES + v
        uv = W_INPUT * LANES + v
        dv = W_SLOPE * LANES + v
        av = W_OUTPUT * LANES + v
        q0, q1, q2, q3 = (
            w[X_QUAT * LANES + xv],
            w[(X_QUAT + 1) * LANES + xv],
            w[(X_QUAT + 2) * LANES + xv],
            w[(X_QUAT + 3) * LANES + xv],
        )
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = _dcm_entries(q0, q1, q2, q3)
        rho = w[U_AIR_DENSITY * LANES + uv]
        density_ratio = rho * w[P_RHO_REF_INV * LANES + pv]

        # Propulsion: shaft power sets the battery load, the battery voltage sets motor speed.
        ct = w[P_CT * LANES + pv] * density_ratio
        cq = w[P_CQ * LANES + pv] * density_ratio
        shaft_w = (
            _shaft_power(w, v, 0, cq)
            + _shaft_power(w, v, 1, cq)
            + _shaft_power(w, v, 2, cq)
            + _shaft_power(w, v, 3, cq)
        )
        if rotors > 4:
            shaft_w += _shaft_power(w, v, 4, cq)
        if rotors > 5:
            shaft_w += _shaft_power(w, v, 5, cq)
        if rotors > 6:
            shaft_w += _shaft_power(w, v, 6, cq)
        if rotors > 7:
            shaft_w += _shaft_power(w, v, 7, cq)
        load_w = shaft_w * w[P_EFFICIENCY_INV * LANES + pv] + w[P_AVIONICS_W * LANES + pv]
        voltage, current = battery_terminal(w, pv, w[X_CHARGE_USED * LANES + xv], load_w)
        voltage_ratio = voltage * w[P_CURVE_VOLTAGE_INV * LANES + pv]

        # Air-relative velocity in the body frame.
        va_n = w[X_VEL * LANES + xv] - w[U_WIND * LANES + uv]
        va_e = w[(X_VEL + 1) * LANES + xv] - w[(U_WIND + 1) * LANES + uv]
        va_d = w[(X_VEL + 2) * LANES + xv] - w[(U_WIND + 2) * LANES + uv]
        vb0 = r00 * va_n + r10 * va_e + r20 * va_d
        vb1 = r01 * va_n + r11 * va_e + r21 * va_d
        vb2 = r02 * va_n + r12 * va_e + r22 * va_d

        # Body drag, quadratic per axis, then each rotor's force and moment.
        half_rho = 0.5 * rho
        fm = (
            -half_rho * w[P_DRAG_AREA * LANES + pv] * abs(vb0) * vb0,
            -half_rho * w[(P_DRAG_AREA + 1) * LANES + pv] * abs(vb1) * vb1,
            -half_rho * w[(P_DRAG_AREA + 2) * LANES + pv] * abs(vb2) * vb2,
            0.0,
            0.0,
            0.0,
            0.0,
        )
        # Written out rotor by rotor: a loop here would be the innermost one, and LLVM
        # vectorizes only innermost loops (the lanes' loop is the one to vectorize). The
        # tests of ``rotors`` fold away for a compile-time count.
        fm = _add_rotor(w, v, 0, ct, cq, voltage_ratio, vb0, vb1, vb2, fm)
        fm = _add_rotor(w, v, 1, ct, cq, voltage_ratio, vb0, vb1, vb2, fm)
        fm = _add_rotor(w, v, 2, ct, cq, voltage_ratio, vb0, vb1, vb2, fm)
        fm = _add_rotor(w, v, 3, ct, cq, voltage_ratio, vb0, vb1, vb2, fm)
        if rotors > 4:
            fm = _add_rotor(w, v, 4, ct, cq, voltage_ratio, vb0, vb1, vb2, fm)
        if rotors > 5:
            fm = _add_rotor(w, v, 5, ct, cq, voltage_ratio, vb0, vb1, vb2, fm)
        if rotors > 6:
            fm = _add_rotor(w, v, 6, ct, cq, voltage_ratio, vb0, vb1, vb2, fm)
        if rotors > 7:
            fm = _add_rotor(w, v, 7, ct, cq, voltage_ratio, vb0, vb1, vb2, fm)
        fx, fy, fz, mx, my, mz, rotor_momentum_z = fm

        p_ = w[X_RATE * LANES + xv]
        q_ = w[(X_RATE + 1) * LANES + xv]
        r_ = w[(X_RATE + 2) * LANES + xv]
        mx -= w[P_ANGULAR_DRAG * LANES + pv] * abs(p_) * p_
        my -= w[(P_ANGULAR_DRAG + 1) * LANES + pv] * abs(q_) * q_
        mz -= w[(P_ANGULAR_DRAG + 2) * LANES + pv] * abs(r_) * r_
        w[A_FORCE_FRD * LANES + av] = fx
        w[(A_FORCE_FRD + 1) * LANES + av] = fy
        w[(A_FORCE_FRD + 2) * LANES + av] = fz
        w[A_MOMENT_FRD * LANES + av] = mx
        w[(A_MOMENT_FRD + 1) * LANES + av] = my
        w[(A_MOMENT_FRD + 2) * LANES + av] = mz
        w[A_VOLTAGE * LANES + av] = voltage
        w[A_CURRENT * LANES + av] = current
        w[A_AIR_DENSITY * LANES + av] = rho
        w[X_CHARGE_USED * LANES + dv] = current

        # Rigid body: I·ω̇ = M - ω × (I·ω + h_rotors).
        i_ = P_INERTIA
        hx = w[i_ * LANES + pv] * p_ + w[(i_ + 1) * LANES + pv] * q_ + w[(i_ + 2) * LANES + pv] * r_
        hy = (
            w[(i_ + 3) * LANES + pv] * p_
            + w[(i_ + 4) * LANES + pv] * q_
            + w[(i_ + 5) * LANES + pv] * r_
        )
        hz = (
            w[(i_ + 6) * LANES + pv] * p_
            + w[(i_ + 7) * LANES + pv] * q_
            + w[(i_ + 8) * LANES + pv] * r_
            + rotor_momentum_z
        )
        tx = mx - (q_ * hz - r_ * hy)
        ty = my - (r_ * hx - p_ * hz)
        tz = mz - (p_ * hy - q_ * hx)
        n_ = P_INERTIA_INV
        mass_inv = w[P_MASS_INV * LANES + pv]
        if mount == MOUNT_FREE:
            w[X_RATE * LANES + dv] = (
                w[n_ * LANES + pv] * tx
                + w[(n_ + 1) * LANES + pv] * ty
                + w[(n_ + 2) * LANES + pv] * tz
            )
            w[(X_RATE + 1) * LANES + dv] = (
                w[(n_ + 3) * LANES + pv] * tx
                + w[(n_ + 4) * LANES + pv] * ty
                + w[(n_ + 5) * LANES + pv] * tz
            )
            w[(X_RATE + 2) * LANES + dv] = (
                w[(n_ + 6) * LANES + pv] * tx
                + w[(n_ + 7) * LANES + pv] * ty
                + w[(n_ + 8) * LANES + pv] * tz
            )
            an = (r00 * fx + r01 * fy + r02 * fz) * mass_inv
            ae = (r10 * fx + r11 * fy + r12 * fz) * mass_inv
            ad = (r20 * fx + r21 * fy + r22 * fz) * mass_inv + STANDARD_GRAVITY_MPS2
        else:
            # Benches hold the centre of mass still. A gimbal leaves one body axis free;
            # about a fixed principal-frame axis e the motion is I_ee·ω̇ = e·M (gyroscopic
            # terms of a rotation about e itself have no e component).
            w[X_RATE * LANES + dv] = 0.0
            w[(X_RATE + 1) * LANES + dv] = 0.0
            w[(X_RATE + 2) * LANES + dv] = 0.0
            if mount == MOUNT_GIMBAL_PITCH:
                w[(X_RATE + 1) * LANES + dv] = ty / w[(i_ + 4) * LANES + pv]
            elif mount == MOUNT_GIMBAL_ROLL:
                w[X_RATE * LANES + dv] = tx / w[i_ * LANES + pv]
            an = 0.0
            ae = 0.0
            ad = 0.0
        w[X_POS * LANES + dv] = w[X_VEL * LANES + xv]
        w[(X_POS + 1) * LANES + dv] = w[(X_VEL + 1) * LANES + xv]
        w[(X_POS + 2) * LANES + dv] = w[(X_VEL + 2) * LANES + xv]
        w[X_VEL * LANES + dv] = an
        w[(X_VEL + 1) * LANES + dv] = ae
        w[(X_VEL + 2) * LANES + dv] = ad
        w[A_ACCEL_NED * LANES + av] = an
        w[(A_ACCEL_NED + 1) * LANES + av] = ae
        w[(A_ACCEL_NED + 2) * LANES + av] = ad
        # q̇ = ½ q ⊗ (0, ω)
        w[X_QUAT * LANES + dv] = 0.5 * (-q1 * p_ - q2 * q_ - q3 * r_)
        w[(X_QUAT + 1) * LANES + dv] = 0.5 * (q0 * p_ + q2 * r_ - q3 * q_)
        w[(X_QUAT + 2) * LANES + dv] = 0.5 * (q0 * q_ - q1 * r_ + q3 * p_)
        w[(X_QUAT + 3) * LANES + dv] = 0.5 * (q0 * r_ + q1 * q_ - q2 * p_)


@_kernel
def _dryden(w: np.ndarray, v: int, n0: float, n1: float, n2: float, dt: float) -> None:
    """Advance lane ``v``'s Dryden shaping filters one step (Euler-Maruyama), add the gust.

    Low-altitude MIL-F-8785C: σ_w = 0.1·W20, σ_u = σ_v = σ_w/(0.177 + 0.000823h)^0.4,
    L_w = h, L_u = L_v = h/(0.177 + 0.000823h)^1.2 (h in ft, 10-1000 ft). u runs along the
    mean wind, v across it, w down. Filters are scaled so each output has variance σ².
    ``n0..n2`` are standard normal draws (zero with ``dt`` = 0: the gust of the state now).
    """
    xv = W_STATE * LANES + v
    pv = W_PARAMS * LANES + v
    uv = W_INPUT * LANES + v
    w20 = w[P_W20 * LANES + pv]
    if w20 > 0.0:
        steady_n = w[P_WIND_STEADY * LANES + pv]
        steady_e = w[(P_WIND_STEADY + 1) * LANES + pv]
        h_ft = min(max(-w[(X_POS + 2) * LANES + xv] / _FT, 10.0), 1000.0)
        factor = 0.177 + 0.000823 * h_ft
        sigma_w = 0.1 * w20
        sigma_uv = sigma_w / factor**0.4
        length_uv = h_ft / factor**1.2 * _FT
        length_w = h_ft * _FT
        airspeed = math.sqrt(
            (w[X_VEL * LANES + xv] - steady_n) ** 2
            + (w[(X_VEL + 1) * LANES + xv] - steady_e) ** 2
            + w[(X_VEL + 2) * LANES + xv] ** 2
        )
        airspeed = max(airspeed, DRYDEN_MIN_AIRSPEED_MPS)
        tau_uv = length_uv / airspeed
        tau_w = length_w / airspeed
        sqrt_dt = math.sqrt(dt)
        t = X_TURBULENCE
        # u: first-order, ż = (-z + n)/τ, y = σ·√(2τ)·z has variance σ².
        w[t * LANES + xv] += (-w[t * LANES + xv] * dt + n0 * sqrt_dt) / tau_uv
        gust_u = sigma_uv * math.sqrt(2.0 * tau_uv) * w[t * LANES + xv]
        # v, w: (1 + √3τs)/(1 + τs)², y = σ·√τ·(z1 + √3·τ·z2) has variance σ².
        z1 = w[(t + 1) * LANES + xv]
        z2 = w[(t + 2) * LANES + xv]
        w[(t + 1) * LANES + xv] = z1 + z2 * dt
        w[(t + 2) * LANES + xv] = z2 + (-(z1 + 2.0 * tau_uv * z2) * dt + n1 * sqrt_dt) / (
            tau_uv * tau_uv
        )
        gust_v = sigma_uv * math.sqrt(tau_uv) * (z1 + _SQRT3 * tau_uv * z2)
        z1 = w[(t + 3) * LANES + xv]
        z2 = w[(t + 4) * LANES + xv]
        w[(t + 3) * LANES + xv] = z1 + z2 * dt
        w[(t + 4) * LANES + xv] = z2 + (-(z1 + 2.0 * tau_w * z2) * dt + n2 * sqrt_dt) / (
            tau_w * tau_w
        )
        gust_w = sigma_w * math.sqrt(tau_w) * (z1 + _SQRT3 * tau_w * z2)
        horizontal = math.hypot(steady_n, steady_e)
        cos_h = steady_n / horizontal if horizontal > 0.0 else 1.0
        sin_h = steady_e / horizontal if horizontal > 0.0 else 0.0
        w[U_WIND * LANES + uv] += gust_u * cos_h - gust_v * sin_h
        w[(U_WIND + 1) * LANES + uv] += gust_u * sin_h + gust_v * cos_h
        w[(U_WIND + 2) * LANES + uv] += gust_w


@_kernel
def _air(w: np.ndarray, noise: np.ndarray, first: int, step: int, dt: float, lanes: int) -> None:
    """The air each lane flies through for the next substep: wind and density.

    Like the throttles, both are held over the substep's four derivative evaluations
    (the altitude moves < 1 mm in 0.2 ms: a density change below 1e-7). Turbulence draws
    ``noise[first + lane, step]``; ``dt`` = 0 gives the wind of the state now.
    """
    turbulent = False
    for v in range(lanes):
        pv = W_PARAMS * LANES + v
        uv = W_INPUT * LANES + v
        w[U_WIND * LANES + uv] = w[P_WIND_STEADY * LANES + pv]
        w[(U_WIND + 1) * LANES + uv] = w[(P_WIND_STEADY + 1) * LANES + pv]
        w[(U_WIND + 2) * LANES + uv] = w[(P_WIND_STEADY + 2) * LANES + pv]
        down_m = w[(W_STATE + X_POS + 2) * LANES + v]
        w[U_AIR_DENSITY * LANES + uv] = air_density_kgpm3(w, pv, down_m)
        turbulent |= w[P_W20 * LANES + pv] > 0.0
    if not turbulent:  # the pow calls of the filters only where there is turbulence
        return
    if dt > 0.0:
        for v in range(lanes):
            k = first + v
            _dryden(w, v, noise[k, step, 0], noise[k, step, 1], noise[k, step, 2], dt)
    else:
        for v in range(lanes):
            _dryden(w, v, 0.0, 0.0, 0.0, 0.0)


# The scratch's regions as flat offsets, for the loops that treat a region's slots alike.
_STATE = W_STATE * LANES
_STAGE = W_STAGE * LANES
_SLOPE = W_SLOPE * LANES
_SLOPE_SUM = W_SLOPE_SUM * LANES
_N_DYN = X_DYN * LANES


@_kernel
def _rk4_step(w: np.ndarray, mount: int, rotors: int, dt: float, lanes: int) -> None:
    """One classic RK4 substep of every lane, then the quaternion renormalized, rotor speeds
    kept >= 0 and rotor angles wrapped.

    Each stage's derivative writes its slope to the same rows; the loop after it adds the
    slope to the weighted sum k1 + 2·k2 + 2·k3 (in that order, so the sum is the classic
    formula's) and sets the next stage state. These loops run over whole rows of all
    LANES lanes (a part chunk's unused lanes compute harmless numbers that are never read
    back): with a fixed trip count on one array LLVM emits them as plain SIMD code.
    """
    half = 0.5 * dt
    for i in range(_N_DYN):
        w[_STAGE + i] = w[_STATE + i]
    derivative(w, mount, rotors, lanes)
    for i in range(_N_DYN):
        w[_SLOPE_SUM + i] = w[_SLOPE + i]
        w[_STAGE + i] = w[_STATE + i] + half * w[_SLOPE + i]
    derivative(w, mount, rotors, lanes)
    for i in range(_N_DYN):
        w[_SLOPE_SUM + i] += 2.0 * w[_SLOPE + i]
        w[_STAGE + i] = w[_STATE + i] + half * w[_SLOPE + i]
    derivative(w, mount, rotors, lanes)
    for i in range(_N_DYN):
        w[_SLOPE_SUM + i] += 2.0 * w[_SLOPE + i]
        w[_STAGE + i] = w[_STATE + i] + dt * w[_SLOPE + i]
    derivative(w, mount, rotors, lanes)
    for i in range(_N_DYN):
        w[_STATE + i] += dt / 6.0 * (w[_SLOPE_SUM + i] + w[_SLOPE + i])
    for v in range(lanes):
        xv = _STATE + v
        q = X_QUAT
        norm = math.sqrt(
            w[q * LANES + xv] * w[q * LANES + xv]
            + w[(q + 1) * LANES + xv] * w[(q + 1) * LANES + xv]
            + w[(q + 2) * LANES + xv] * w[(q + 2) * LANES + xv]
            + w[(q + 3) * LANES + xv] * w[(q + 3) * LANES + xv]
        )
        for j in range(4):
            w[(q + j) * LANES + xv] /= norm
        for i in range(rotors):
            w[(X_ROTOR_SPEED + i) * LANES + xv] = max(w[(X_ROTOR_SPEED + i) * LANES + xv], 0.0)
            # Python's angle % 2π (exactly so for one turn per step: a - 2π is exact there),
            # as arithmetic the vector units have instead of a libm fmod call.
            angle = w[(X_ROTOR_ANGLE + i) * LANES + xv]
            w[(X_ROTOR_ANGLE + i) * LANES + xv] = angle - _TWO_PI * np.floor(angle * _PER_TURN)


@_kernel
def _ground_contact(w: np.ndarray, dt: float, lanes: int) -> None:
    """The ground plane z = 0 (home): no sinking, no bounce, no sliding while resting.

    A vehicle that reaches the ground stays on it (inelastic contact), with the attitude
    it landed with, while its thrust cannot lift it. Its legs and the ground's friction
    take off its speed into and along the ground at LANDING_DECELERATION_MPS2 (the force
    they push with, per unit mass), not within one step: so the accelerometer feels the
    touchdown, and an estimator that integrates it stops descending with the vehicle
    (PX4's land detector waits for that). The legs' few centimetres of give are not
    modelled: the body stays at z = 0.
    """
    bleed = LANDING_DECELERATION_MPS2 * dt
    for v in range(lanes):
        xv = _STATE + v
        if w[(X_POS + 2) * LANES + xv] >= 0.0:
            w[(X_POS + 2) * LANES + xv] = 0.0
            vn = w[X_VEL * LANES + xv]
            ve = w[(X_VEL + 1) * LANES + xv]
            vd = max(w[(X_VEL + 2) * LANES + xv], 0.0)  # into the ground; a lift-off is free
            speed = math.sqrt(vn * vn + ve * ve + vd * vd)
            scale = max(speed - bleed, 0.0) / speed if speed > 0.0 else 0.0
            w[X_VEL * LANES + xv] = vn * scale
            w[(X_VEL + 1) * LANES + xv] = ve * scale
            w[(X_VEL + 2) * LANES + xv] = min(w[(X_VEL + 2) * LANES + xv], 0.0) + vd * scale
            w[X_RATE * LANES + xv] = 0.0
            w[(X_RATE + 1) * LANES + xv] = 0.0
            w[(X_RATE + 2) * LANES + xv] = 0.0
            w[X_ON_GROUND * LANES + xv] = 1.0
        else:
            w[X_ON_GROUND * LANES + xv] = 0.0


@_kernel
def _outputs(w: np.ndarray, duration: float, lanes: int) -> None:
    """Outputs at the final state that the derivative does not give: on the ground the
    acceleration the contact allowed (the velocity's change over the advance: 0 at rest, the
    legs' deceleration in a touchdown), the wind, and the specific force f = Rᵀ·(a - g)
    ((0, 0, -g) level at rest)."""
    per_second = 1.0 / duration if duration > 0.0 else 0.0
    for v in range(lanes):
        xv = _STATE + v
        av = W_OUTPUT * LANES + v
        uv = W_INPUT * LANES + v
        if w[X_ON_GROUND * LANES + xv] > 0.0:
            for axis in range(3):
                change = w[(X_VEL + axis) * LANES + xv] - w[(W_VEL_START + axis) * LANES + v]
                w[(A_ACCEL_NED + axis) * LANES + av] = change * per_second
        w[A_WIND_NED * LANES + av] = w[U_WIND * LANES + uv]
        w[(A_WIND_NED + 1) * LANES + av] = w[(U_WIND + 1) * LANES + uv]
        w[(A_WIND_NED + 2) * LANES + av] = w[(U_WIND + 2) * LANES + uv]
        q = X_QUAT
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = _dcm_entries(
            w[q * LANES + xv],
            w[(q + 1) * LANES + xv],
            w[(q + 2) * LANES + xv],
            w[(q + 3) * LANES + xv],
        )
        an = w[A_ACCEL_NED * LANES + av]
        ae = w[(A_ACCEL_NED + 1) * LANES + av]
        ad = w[(A_ACCEL_NED + 2) * LANES + av] - STANDARD_GRAVITY_MPS2
        w[A_SPECIFIC_FORCE * LANES + av] = r00 * an + r10 * ae + r20 * ad
        w[(A_SPECIFIC_FORCE + 1) * LANES + av] = r01 * an + r11 * ae + r21 * ad
        w[(A_SPECIFIC_FORCE + 2) * LANES + av] = r02 * an + r12 * ae + r22 * ad


@_kernel
def _substeps(
    w: np.ndarray,
    noise: np.ndarray,
    first: int,
    mount: int,
    rotors: int,
    n_steps: int,
    dt: float,
    lanes: int,
) -> None:
    """``n_steps`` substeps of a chunk's scratch, then the outputs at the final state."""
    for axis in range(3):
        for v in range(lanes):
            w[(W_VEL_START + axis) * LANES + v] = w[(X_VEL + axis) * LANES + _STATE + v]
    for step in range(n_steps):
        _air(w, noise, first, step, dt, lanes)
        _rk4_step(w, mount, rotors, dt, lanes)
        if mount == MOUNT_FREE:
            _ground_contact(w, dt, lanes)
    _air(w, noise, first, 0, 0.0, lanes)
    for i in range(_N_DYN):
        w[_STAGE + i] = w[_STATE + i]
    derivative(w, mount, rotors, lanes)
    _outputs(w, n_steps * dt, lanes)


@_kernel
def _substeps_of(
    w: np.ndarray,
    noise: np.ndarray,
    first: int,
    mount: int,
    rotors: int,
    n_steps: int,
    dt: float,
    lanes: int,
) -> None:
    """:func:`_substeps` with the rotor count (one of ROTOR_COUNTS) as a compile-time
    constant, as :func:`_advance_chunk` does with the lane count."""
    if rotors == 4:
        _substeps(w, noise, first, mount, 4, n_steps, dt, lanes)
    elif rotors == 6:
        _substeps(w, noise, first, mount, 6, n_steps, dt, lanes)
    else:
        _substeps(w, noise, first, mount, 8, n_steps, dt, lanes)


@_kernel
def _advance_chunk(
    states: np.ndarray,
    outputs: np.ndarray,
    params: np.ndarray,
    throttles: np.ndarray,
    noise: np.ndarray,
    work: np.ndarray,
    chunk: int,
    mount: int,
    n_steps: int,
    dt: float,
) -> None:
    """Run vehicles ``chunk·LANES ...`` through ``n_steps`` substeps on the chunk's scratch.

    The scratch is one flat array, slot-major ([slot·LANES + lane]), and the kernels index
    it at fixed offsets: LLVM sees that the slots never overlap and vectorizes without
    overlap checks.
    """
    first = chunk * LANES
    lanes = min(LANES, states.shape[1] - first)
    w = work[chunk]
    for j in range(X_SIZE):
        for v in range(lanes):
            w[(W_STATE + j) * LANES + v] = states[j, first + v]
    for j in range(P_SIZE):
        for v in range(lanes):
            w[(W_PARAMS + j) * LANES + v] = params[j, first + v]
    rotors = throttles.shape[0]
    for i in range(rotors):
        for v in range(lanes):
            w[(W_INPUT + U_THROTTLE + i) * LANES + v] = throttles[i, first + v]
    # A whole chunk passes its lane count as a compile-time constant: numba compiles the
    # helpers again for it, and LLVM turns each lane loop into straight SIMD code, without
    # the trip-count tests and scalar remainders of a loop of unknown length. A part chunk
    # runs the same source with a run-time count; both do the same IEEE operations.
    if lanes == LANES:
        _substeps_of(w, noise, first, mount, rotors, n_steps, dt, LANES)
    else:
        _substeps_of(w, noise, first, mount, rotors, n_steps, dt, lanes)
    for j in range(X_SIZE):
        for v in range(lanes):
            states[j, first + v] = w[(W_STATE + j) * LANES + v]
    for j in range(A_SIZE):
        for v in range(lanes):
            outputs[j, first + v] = w[(W_OUTPUT + j) * LANES + v]


@_kernel
def _finite(a: np.ndarray) -> bool:
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

    Arrays are [slot, vehicle] (``throttles`` one row per rotor slot the batch uses,
    ``noise`` [vehicle, step, 3], ``work`` one scratch block per chunk of LANES vehicles).
    Returns False, without touching any state, when a
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
