"""The vehicle model users drive: one vehicle (:class:`QuadModel`) or many (:class:`QuadBatch`).

Both hold ESC throttles constant over ``advance(command, duration_s)`` and run the compiled
5 kHz RK4 loop in one call, the way the rig's lockstep holds PX4's motor outputs for one
autopilot frame. Ground truth comes back as :class:`VehicleTruth` with named SI fields.

Time is counted in whole physics steps, never summed from float durations: a float sum
drifts by more than a nanosecond within minutes and a sensor slot on the frame grid would
then be missed (it was, at 575 s). Frames and sensor slots are whole microseconds.
"""

import enum
import math
from collections.abc import Sequence
from typing import TypedDict, Unpack

import numpy as np
from numpy.typing import ArrayLike, NDArray

from quad_model import dynamics as dyn
from quad_model.environment import Environment
from quad_model.frames import STANDARD_GRAVITY_MPS2
from quad_model.vehicle import BatteryParams, Vehicle

DEFAULT_PHYSICS_RATE_HZ = 5000
#: Above this many vehicles the batch runs on all cores (thread start-up costs ~10 µs).
PARALLEL_MIN_VEHICLES = 32


class ModelInputError(ValueError):
    """A command, duration or setting handed to the model is unusable; the message says which."""


class Mount(enum.IntEnum):
    """How the vehicle is held: free flight or one of the paper's test benches."""

    FREE = dyn.MOUNT_FREE
    #: 1-DOF bearing through the centre of mass along body y: only pitch is free.
    GIMBAL_PITCH = dyn.MOUNT_GIMBAL_PITCH
    #: 1-DOF bearing along body x: only roll is free.
    GIMBAL_ROLL = dyn.MOUNT_GIMBAL_ROLL
    #: Rigidly clamped; ``force_frd_n``/``moment_frd_nm`` are what the load cell reads.
    THRUST_STAND = dyn.MOUNT_THRUST_STAND


class VehicleTruth:
    """Ground truth of one vehicle at ``time_s`` (SI units, NED world, FRD body).

    A read-only snapshot: the rig takes one per frame, so it copies two rows and names
    their slots lazily instead of building twenty arrays.
    """

    __slots__ = ("_outputs", "_rotors", "_state")

    def __init__(
        self, state: NDArray[np.float64], outputs: NDArray[np.float64], rotors: int
    ) -> None:
        self._state = state.copy()
        self._outputs = outputs.copy()
        self._rotors = rotors
        self._state.flags.writeable = False
        self._outputs.flags.writeable = False

    def __repr__(self) -> str:
        return (
            f"VehicleTruth(time_s={self.time_s:.6f}, position_ned_m={self.position_ned_m}, "
            f"velocity_ned_mps={self.velocity_ned_mps}, on_ground={self.on_ground})"
        )

    @property
    def time_us(self) -> int:
        """Simulated time in whole µs (exact at frame ends, which fall on whole µs)."""
        # item(): Python's round of a float takes a tenth of numpy's round of a float64,
        # and the sensor models ask for the time several times a frame.
        return round(self._state.item(dyn.X_TIME_US))

    @property
    def time_s(self) -> float:
        return float(self._state[dyn.X_TIME_US]) / 1e6

    @property
    def position_ned_m(self) -> NDArray[np.float64]:
        return self._state[dyn.X_POS : dyn.X_POS + 3]

    @property
    def velocity_ned_mps(self) -> NDArray[np.float64]:
        return self._state[dyn.X_VEL : dyn.X_VEL + 3]

    @property
    def acceleration_ned_mps2(self) -> NDArray[np.float64]:
        return self._outputs[dyn.A_ACCEL_NED : dyn.A_ACCEL_NED + 3]

    @property
    def attitude_quat(self) -> NDArray[np.float64]:
        """Body→NED, Hamilton, (w, x, y, z)."""
        return self._state[dyn.X_QUAT : dyn.X_QUAT + 4]

    @property
    def angular_rate_frd_radps(self) -> NDArray[np.float64]:
        return self._state[dyn.X_RATE : dyn.X_RATE + 3]

    @property
    def specific_force_frd_mps2(self) -> NDArray[np.float64]:
        """What an ideal accelerometer reads: level at rest ≈ (0, 0, -9.81)."""
        return self._outputs[dyn.A_SPECIFIC_FORCE : dyn.A_SPECIFIC_FORCE + 3]

    @property
    def rotor_speed_radps(self) -> NDArray[np.float64]:
        return self._state[dyn.X_ROTOR_SPEED : dyn.X_ROTOR_SPEED + self._rotors]

    @property
    def rotor_angle_rad(self) -> NDArray[np.float64]:
        """Rotor angle in each rotor's own spin direction, 0..2π (phase of the vibration)."""
        return self._state[dyn.X_ROTOR_ANGLE : dyn.X_ROTOR_ANGLE + self._rotors]

    @property
    def rotor_thrust_n(self) -> NDArray[np.float64]:
        return self._outputs[dyn.A_THRUST : dyn.A_THRUST + self._rotors]

    @property
    def rotor_torque_nm(self) -> NDArray[np.float64]:
        return self._outputs[dyn.A_TORQUE : dyn.A_TORQUE + self._rotors]

    @property
    def force_frd_n(self) -> NDArray[np.float64]:
        """Propulsion + aerodynamic force on the body (what a thrust stand reads)."""
        return self._outputs[dyn.A_FORCE_FRD : dyn.A_FORCE_FRD + 3]

    @property
    def moment_frd_nm(self) -> NDArray[np.float64]:
        """Propulsion + aerodynamic moment about the centre of mass."""
        return self._outputs[dyn.A_MOMENT_FRD : dyn.A_MOMENT_FRD + 3]

    @property
    def battery_voltage_v(self) -> float:
        return float(self._outputs[dyn.A_VOLTAGE])

    @property
    def battery_current_a(self) -> float:
        return float(self._outputs[dyn.A_CURRENT])

    @property
    def battery_charge_used_c(self) -> float:
        return float(self._state[dyn.X_CHARGE_USED])

    @property
    def wind_ned_mps(self) -> NDArray[np.float64]:
        return self._outputs[dyn.A_WIND_NED : dyn.A_WIND_NED + 3]

    @property
    def air_density_kgpm3(self) -> float:
        return float(self._outputs[dyn.A_AIR_DENSITY])

    @property
    def on_ground(self) -> bool:
        return bool(self._state[dyn.X_ON_GROUND] > 0.0)


def charge_used_for_voltage_c(battery: BatteryParams, voltage_v: float) -> float:
    """Charge already drawn (C) from a pack whose open-circuit voltage is ``voltage_v``.

    The inverse of :func:`quad_model.dynamics.open_circuit_voltage`, so a model can start
    from a measured resting voltage instead of full. Raises :class:`ModelInputError` when
    the voltage lies outside the pack's empty..full range.
    """
    empty_v = battery.cell_count * battery.cell_empty_v
    full_v = battery.cell_count * battery.cell_full_v
    if not empty_v <= voltage_v <= full_v:  # also refuses NaN
        raise ModelInputError(
            f"battery_voltage_v={voltage_v:g} V is outside the pack's open-circuit range "
            f"{empty_v:g}..{full_v:g} V ({battery.cell_count} cells × "
            f"{battery.cell_empty_v:g}..{battery.cell_full_v:g} V)"
        )
    state_of_charge = (voltage_v - empty_v) / (full_v - empty_v)
    return (1.0 - state_of_charge) * battery.capacity_ah * 3600.0


def pack_params(vehicle: Vehicle, environment: Environment) -> NDArray[np.float64]:
    """One row of kernel parameters (layout in :mod:`quad_model.dynamics`)."""
    body, prop, bat = vehicle.body, vehicle.propulsion, vehicle.battery
    p = np.zeros(dyn.P_SIZE)
    inertia = np.array(body.inertia_kgm2)
    p[dyn.P_MASS] = body.mass_kg
    p[dyn.P_INERTIA : dyn.P_INERTIA + 9] = inertia.ravel()
    p[dyn.P_INERTIA_INV : dyn.P_INERTIA_INV + 9] = np.linalg.inv(inertia).ravel()
    p[dyn.P_DRAG_AREA : dyn.P_DRAG_AREA + 3] = body.drag_area_m2
    p[dyn.P_ANGULAR_DRAG : dyn.P_ANGULAR_DRAG + 3] = body.angular_drag_nms2
    n = prop.rotor_count
    p[dyn.P_ROTOR_POS : dyn.P_ROTOR_POS + 3 * n] = np.ravel(prop.position_frd_m)
    p[dyn.P_SPIN : dyn.P_SPIN + n] = prop.spin_direction
    p[dyn.P_THRUST_FACTOR : dyn.P_THRUST_FACTOR + n] = prop.thrust_factors
    p[dyn.P_TORQUE_FACTOR : dyn.P_TORQUE_FACTOR + n] = prop.torque_factors
    p[dyn.P_CT] = prop.thrust_coefficient_n_per_radps2
    p[dyn.P_CQ] = prop.torque_coefficient_nm_per_radps2
    p[dyn.P_RHO_REF] = prop.reference_air_density_kgpm3
    p[dyn.P_ROTOR_INERTIA] = prop.rotor_inertia_kgm2
    p[dyn.P_MOTOR_TAU] = prop.motor_time_constant_s
    p[dyn.P_SPEED_SLOPE] = prop.speed_slope_radps
    p[dyn.P_SPEED_OFFSET] = prop.speed_offset_radps
    p[dyn.P_MIN_THROTTLE] = prop.min_throttle
    p[dyn.P_CURVE_VOLTAGE] = prop.speed_curve_voltage_v
    p[dyn.P_ROTOR_DRAG] = prop.rotor_drag_coefficient_ns_per_m_rad
    p[dyn.P_AXIAL_INFLOW] = prop.axial_inflow_coefficient_ns_per_m_rad
    p[dyn.P_CELLS] = bat.cell_count
    p[dyn.P_CAPACITY_C] = bat.capacity_ah * 3600.0
    p[dyn.P_CELL_FULL] = bat.cell_full_v
    p[dyn.P_CELL_EMPTY] = bat.cell_empty_v
    p[dyn.P_R_INTERNAL] = bat.internal_resistance_ohm
    p[dyn.P_EFFICIENCY] = bat.propulsion_efficiency
    p[dyn.P_AVIONICS_W] = bat.avionics_power_w
    p[dyn.P_SPEED_SCALE : dyn.P_SPEED_SCALE + n] = 1.0
    p[dyn.P_HOME_ALT] = environment.home.alt_amsl_m
    p[dyn.P_WIND_STEADY : dyn.P_WIND_STEADY + 3] = environment.wind.steady_ned_mps
    p[dyn.P_W20] = environment.wind.wind_at_6m_mps
    p[dyn.P_TEMP_OFFSET] = environment.temperature_offset_k
    for inverse, value in (
        (dyn.P_MASS_INV, dyn.P_MASS),
        (dyn.P_RHO_REF_INV, dyn.P_RHO_REF),
        (dyn.P_MOTOR_TAU_INV, dyn.P_MOTOR_TAU),
        (dyn.P_CURVE_VOLTAGE_INV, dyn.P_CURVE_VOLTAGE),
        (dyn.P_CAPACITY_C_INV, dyn.P_CAPACITY_C),
        (dyn.P_EFFICIENCY_INV, dyn.P_EFFICIENCY),
    ):
        p[inverse] = 1.0 / p[value]
    return p


class QuadBatch:
    """N vehicles stepped together by one compiled call (campaigns, Monte-Carlo).

    ``vehicles`` is one vehicle for all N, or one per row (parameter dispersion), of any
    rotor counts: the throttles have a column per rotor of the vehicle with the most
    (:attr:`rotors`), and a vehicle with fewer leaves the columns past its own unused
    (its results are the same as alone, bit for bit). All start at rest on the ground at
    home, level, facing north, battery full. Randomness (turbulence) comes only from
    ``rng``, drawn in vehicle order, so a seed gives the same numbers on any core count.
    """

    def __init__(
        self,
        vehicles: Vehicle | Sequence[Vehicle],
        count: int,
        rng: np.random.Generator,
        environment: Environment | None = None,
        mount: Mount = Mount.FREE,
        physics_rate_hz: int = DEFAULT_PHYSICS_RATE_HZ,
    ) -> None:
        if count < 1:
            raise ModelInputError(f"count={count} must be at least 1")
        if isinstance(vehicles, Vehicle):
            vehicles = [vehicles] * count
        if len(vehicles) != count:
            raise ModelInputError(f"got {len(vehicles)} vehicles for count={count}")
        if not physics_rate_hz > 0 or physics_rate_hz != int(physics_rate_hz):
            raise ModelInputError(f"physics_rate_hz={physics_rate_hz} must be a whole number > 0")
        self.physics_rate_hz = int(physics_rate_hz)
        self.vehicles = tuple(vehicles)
        self.environment = environment or Environment()
        self.mount = Mount(mount)
        self.physics_dt_s = 1.0 / physics_rate_hz
        #: Time = start + steps / rate, both whole numbers (see the module docstring).
        self._start_us = 0
        self._steps = 0
        self._rng = rng
        # The kernel's arrays are [slot, vehicle] (see quad_model.dynamics); users see
        # [vehicle, slot] views of them.
        rows = {id(v): pack_params(v, self.environment) for v in self.vehicles}
        self._params = np.array([rows[id(v)] for v in self.vehicles]).T.copy()
        self._states = np.zeros((dyn.X_SIZE, count))
        self._outputs = np.zeros((dyn.A_SIZE, count))
        #: Throttle columns: the most rotors any vehicle of the batch has.
        self.rotors = max(v.propulsion.rotor_count for v in self.vehicles)
        self._rotor_counts = np.array([v.propulsion.rotor_count for v in self.vehicles])
        self._throttles = np.zeros((self.rotors, count))
        self.params = self._params.T
        self.states = self._states.T
        self.outputs = self._outputs.T
        self.throttles = self._throttles.T
        #: Thrust fraction of each motor (set_motor_health); the kernel uses its square root.
        self.motor_health = np.ones((count, self.rotors))
        self._work = np.zeros((-(-count // dyn.LANES), dyn.W_SIZE * dyn.LANES))
        self._turbulent = bool(np.any(self.params[:, dyn.P_W20] > 0))
        self._no_noise = np.zeros((count, 0, 3))
        self._kernel = (
            dyn.advance_parallel if count >= PARALLEL_MIN_VEHICLES else dyn.advance_serial
        )
        self._last_duration_s, self._last_n_steps = -1.0, 0
        self.reset()

    @property
    def count(self) -> int:
        return self.states.shape[0]

    def reset(
        self,
        position_ned_m: ArrayLike = (0.0, 0.0, 0.0),
        velocity_ned_mps: ArrayLike = (0.0, 0.0, 0.0),
        attitude_quat: ArrayLike = (1.0, 0.0, 0.0, 0.0),
        angular_rate_frd_radps: ArrayLike = (0.0, 0.0, 0.0),
        rotor_speed_radps: ArrayLike = 0.0,
        time_us: int = 0,
        battery_voltage_v: ArrayLike | None = None,
    ) -> None:
        """Put every vehicle in the given state (each argument broadcasts over vehicles).

        ``battery_voltage_v`` is each pack's open-circuit voltage at the start (None: full),
        e.g. a real flight's resting voltage before arming.
        """
        n = self.count
        s = self.states
        s[:] = 0.0
        s[:, dyn.X_POS : dyn.X_POS + 3] = np.broadcast_to(position_ned_m, (n, 3))
        s[:, dyn.X_VEL : dyn.X_VEL + 3] = np.broadcast_to(velocity_ned_mps, (n, 3))
        quat = np.array(np.broadcast_to(attitude_quat, (n, 4)), dtype=float)
        norms = np.linalg.norm(quat, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-6):
            raise ModelInputError(f"attitude_quat={attitude_quat!s} is not a unit quaternion")
        s[:, dyn.X_QUAT : dyn.X_QUAT + 4] = quat / norms[:, None]
        s[:, dyn.X_RATE : dyn.X_RATE + 3] = np.broadcast_to(angular_rate_frd_radps, (n, 3))
        try:
            speeds = np.broadcast_to(rotor_speed_radps, (n, self.rotors))
        except ValueError:
            raise ModelInputError(
                f"rotor_speed_radps={rotor_speed_radps!s} is not one speed or {self.rotors}"
            ) from None
        if np.any(speeds < 0):
            raise ModelInputError(f"rotor_speed_radps={rotor_speed_radps!s} must be >= 0")
        s[:, dyn.X_ROTOR_SPEED : dyn.X_ROTOR_SPEED + self.rotors] = speeds
        for row, count in zip(s, self._rotor_counts, strict=True):
            row[dyn.X_ROTOR_SPEED + count : dyn.X_ROTOR_SPEED + dyn.ROTORS] = 0.0
        self._start_us, self._steps = int(time_us), 0
        s[:, dyn.X_TIME_US] = self._start_us
        if battery_voltage_v is not None:
            voltages = np.broadcast_to(np.asarray(battery_voltage_v, dtype=float), (n,))
            s[:, dyn.X_CHARGE_USED] = [
                charge_used_for_voltage_c(vehicle.battery, float(voltage))
                for vehicle, voltage in zip(self.vehicles, voltages, strict=True)
            ]
        if not np.all(np.isfinite(s)):
            raise ModelInputError("reset state has a non-finite value")
        if self.mount == Mount.FREE:
            if np.any(s[:, dyn.X_POS + 2] > 0.0):
                raise ModelInputError("position_ned_m is below the ground (z > 0)")
            s[:, dyn.X_ON_GROUND] = s[:, dyn.X_POS + 2] == 0.0
        self.throttles[:] = 0.0
        self.advance(self.throttles, 0.0)

    def advance(self, throttles: ArrayLike, duration_s: float) -> None:
        """Hold ESC throttles (N × :attr:`rotors`, normalized 0..1, PX4 motor order) for
        ``duration_s``.

        Throttles outside 0..1 are clamped, as an ESC does; a non-finite value is refused.
        ``duration_s`` must be a whole number of physics steps (1 ms = 5 steps at 5 kHz).
        """
        command = np.asarray(throttles, dtype=float)
        if command.shape != self.throttles.shape:
            raise ModelInputError(
                f"throttles have shape {command.shape}, expected {self.throttles.shape}"
            )
        self.throttles[:] = command
        self._run(duration_s)

    def _run(self, duration_s: float) -> None:
        """Run the kernel with the throttles already in ``self.throttles``."""
        if duration_s != self._last_duration_s:
            steps = duration_s / self.physics_dt_s
            n_steps = round(steps)
            if abs(steps - n_steps) > 1e-6 or n_steps < 0:
                raise ModelInputError(
                    f"duration_s={duration_s} is not a whole number of "
                    f"{self.physics_dt_s * 1e3:g} ms physics steps"
                )
            self._last_duration_s, self._last_n_steps = duration_s, n_steps
        n_steps = self._last_n_steps
        noise = (
            self._rng.standard_normal((self.count, n_steps, 3))
            if self._turbulent
            else self._no_noise
        )
        if not self._kernel(
            self._states,
            self._outputs,
            self._params,
            self._throttles,
            noise,
            self._work,
            int(self.mount),
            n_steps,
            self.physics_dt_s,
        ):
            raise ModelInputError(
                f"throttles contain a non-finite value: {self.throttles.tolist()}"
            )
        self._steps += n_steps
        elapsed_us = self._steps * 1_000_000 / self.physics_rate_hz  # exact on whole µs
        self.states[:, dyn.X_TIME_US] = self._start_us + elapsed_us

    def set_motor_health(self, vehicle_index: int, motor: int, thrust_fraction: float) -> None:
        """Degrade (0 < f < 1) or kill (0) one motor-propeller unit; 1 restores it.

        ``thrust_fraction`` scales the steady rotor speed by its square root, so thrust,
        torque, current draw and vibration all follow, as with a weak motor or a chipped
        propeller.
        """
        if not 0.0 <= thrust_fraction <= 1.0:
            raise ModelInputError(f"thrust_fraction={thrust_fraction} must be within 0..1")
        rotors = int(self._rotor_counts[vehicle_index])
        if not 0 <= motor < rotors:
            raise ModelInputError(f"motor={motor} must be within 0..{rotors - 1}")
        self.motor_health[vehicle_index, motor] = thrust_fraction
        self.params[vehicle_index, dyn.P_SPEED_SCALE + motor] = math.sqrt(thrust_fraction)

    def truth(self, index: int) -> VehicleTruth:
        """Ground truth of one vehicle (a snapshot: safe to keep)."""
        return VehicleTruth(self.states[index], self.outputs[index], int(self._rotor_counts[index]))

    def hover_throttle(self, index: int = 0) -> float:
        """Throttle at which the healthy rotors, turning alike, carry the weight here and now.

        Solves the propulsion chain backwards at the vehicle's air density and battery
        charge: hover speed from thrust = weight, battery voltage under the hover load,
        then the ESC speed curve at that voltage.
        """
        p, s = self.params[index], self.states[index]
        block = dyn.lane_block(p)
        density = dyn.air_density_kgpm3(block, 0, s[dyn.X_POS + 2])
        density_ratio = density / p[dyn.P_RHO_REF]
        ct, cq = p[dyn.P_CT] * density_ratio, p[dyn.P_CQ] * density_ratio
        thrust_factors = p[dyn.P_THRUST_FACTOR : dyn.P_THRUST_FACTOR + dyn.ROTORS].sum()
        torque_factors = p[dyn.P_TORQUE_FACTOR : dyn.P_TORQUE_FACTOR + dyn.ROTORS].sum()
        speed = math.sqrt(p[dyn.P_MASS] * STANDARD_GRAVITY_MPS2 / (thrust_factors * ct))
        load_w = torque_factors * cq * speed**3 / p[dyn.P_EFFICIENCY] + p[dyn.P_AVIONICS_W]
        voltage, _ = dyn.battery_terminal(block, 0, s[dyn.X_CHARGE_USED], load_w)
        curve_speed = speed * p[dyn.P_CURVE_VOLTAGE] / voltage
        return (curve_speed - p[dyn.P_SPEED_OFFSET]) / p[dyn.P_SPEED_SLOPE]


class _ResetState(TypedDict, total=False):
    """:meth:`QuadBatch.reset`'s keywords, as :meth:`QuadModel.reset` passes them on."""

    position_ned_m: ArrayLike
    velocity_ned_mps: ArrayLike
    attitude_quat: ArrayLike
    angular_rate_frd_radps: ArrayLike
    rotor_speed_radps: ArrayLike
    time_us: int
    battery_voltage_v: ArrayLike | None


class QuadModel:
    """One vehicle at 5 kHz: what the rig's lockstep loop drives.

    >>> from quad_model import QuadModel, load_vehicle
    >>> model = QuadModel(load_vehicle("f450_high_precision"), np.random.default_rng(1))
    >>> model.advance([0.7, 0.7, 0.7, 0.7], 0.001)  # one 1 ms autopilot frame
    >>> model.truth.time_us
    1000
    """

    def __init__(
        self,
        vehicle: Vehicle,
        rng: np.random.Generator,
        environment: Environment | None = None,
        mount: Mount = Mount.FREE,
        physics_rate_hz: int = DEFAULT_PHYSICS_RATE_HZ,
    ) -> None:
        self._batch = QuadBatch(vehicle, 1, rng, environment, mount, physics_rate_hz)
        self.vehicle = vehicle

    @property
    def environment(self) -> Environment:
        return self._batch.environment

    @property
    def mount(self) -> Mount:
        return self._batch.mount

    @property
    def physics_dt_s(self) -> float:
        return self._batch.physics_dt_s

    def reset(self, **state: Unpack[_ResetState]) -> None:
        """Set the state; keywords as :meth:`QuadBatch.reset`."""
        self._batch.reset(**state)

    def advance(self, command: ArrayLike, duration_s: float) -> None:
        """Hold the ESC throttles, one per rotor (0..1, PX4 order), for ``duration_s``."""
        try:
            self._batch.throttles[0] = command
        except ValueError:
            raise ModelInputError(
                f"command {command!r} is not {self._batch.rotors} throttles"
            ) from None
        self._batch._run(duration_s)

    def set_motor_health(self, motor: int, thrust_fraction: float) -> None:
        """Fault hook: see :meth:`QuadBatch.set_motor_health`."""
        self._batch.set_motor_health(0, motor, thrust_fraction)

    @property
    def motor_health(self) -> NDArray[np.float64]:
        return self._batch.motor_health[0].copy()

    @property
    def truth(self) -> VehicleTruth:
        return self._batch.truth(0)

    def hover_throttle(self) -> float:
        """Throttle that balances the weight now: see :meth:`QuadBatch.hover_throttle`."""
        return self._batch.hover_throttle(0)
