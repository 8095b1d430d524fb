"""The flight controller core: sensors in, motor commands out, no sockets.

:meth:`FlightController.update` is one lockstep frame: estimate, run the commander (arming,
modes, failsafes, land detection), take the mode's set-point, run the control cascade and
return the four motor commands in PX4's quad-X order. Ground-station commands are methods
that act at once and take effect in the next frame, so a run is deterministic whatever the
wall clock does. The clock is the sensor time only.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from quad_model.frames import (
    euler_from_quat,
    geodetic_to_ned,
    ned_to_geodetic,
    quat_conjugate,
    quat_multiply,
    quat_to_dcm,
)
from rig.autopilots.reference.control import (
    AngularVelocityFilter,
    AttitudeController,
    ControlAllocator,
    PositionController,
    RateController,
    thrust_to_attitude,
)
from rig.autopilots.reference.estimator import (
    AttitudeEstimator,
    DistanceToGround,
    FlowVelocity,
    GyroRestCalibration,
    OpticalFlowFusion,
    PositionEstimator,
    pressure_altitude_m,
)
from rig.autopilots.reference.flight_log import ImuAverage
from rig.autopilots.reference.land_detector import LandDetector
from rig.autopilots.reference.manual import ManualTask, Sticks
from rig.autopilots.reference.navigator import MissionItem, Navigator, NavState, Setpoint
from rig.autopilots.reference.params import Parameters
from rig.autopilots.reference.sensors import GroundTruth, RangeReading, SensorFrame, SensorMonitor
from rig.logs.ulog_writer import ULogWriter
from rig.mavlink.px4_api import mavlink

#: PX4 runs the position loop on each local-position update, about 50 Hz.
POSITION_LOOP_PERIOD_US = 20_000
#: Rate-loop topics are logged at most this often (PX4's high-rate logger profile: 250 Hz).
FAST_LOG_PERIOD_US = 4_000
#: PX4's magic number that forces arming/disarming past the checks (MAV_CMD 400 param2).
FORCE_MAGIC = 21196
#: Sensor timeouts other than the IMU's (PX4 sensors module: a sensor silent for 1 s is lost).
_SENSOR_TIMEOUT_S = 1.0
#: Time constant of the low-pass on the GPS-derived acceleration (attitude compensation).
_GPS_ACCEL_TAU_S = 0.1
#: Modes that need a position estimate.
_POSITION_MODES = {NavState.POSCTL, NavState.AUTO_MISSION, NavState.AUTO_LOITER,
                   NavState.AUTO_TAKEOFF, NavState.AUTO_LAND, NavState.OFFBOARD}  # fmt: skip
#: Modes flown from a pilot's sticks.
_STICK_MODES = {NavState.POSCTL, NavState.ALTCTL}
_SEVERITY_LEVEL = {mavlink.MAV_SEVERITY_CRITICAL: "crit", mavlink.MAV_SEVERITY_WARNING: "warn",
                   mavlink.MAV_SEVERITY_INFO: "info"}  # fmt: skip


@dataclass(frozen=True)
class Controls:
    """What goes back in HIL_ACTUATOR_CONTROLS: motors 0..1 in PX4's motor order, one per
    rotor of ``CA_ROTOR_COUNT``."""

    motors: tuple[float, ...]
    armed: bool


@dataclass(frozen=True)
class CommandResult:
    """MAV_RESULT of a command, with the reason sent as STATUSTEXT when refused."""

    result: int
    reason: str = ""


@dataclass(frozen=True)
class BodySetpoint:
    """An offboard SET_ATTITUDE_TARGET: an attitude or body rates, and collective thrust 0..1.

    Exactly one of ``q`` and ``rates_radps`` is set: PX4 flies the attitude when it is given,
    else the body rates (rate loop only).
    """

    q: NDArray[np.float64] | None
    rates_radps: NDArray[np.float64] | None
    thrust: float


_ACCEPTED = CommandResult(mavlink.MAV_RESULT_ACCEPTED)


class FlightController:
    """A PX4-style multicopter autopilot driven frame by frame.

    Parameters
    ----------
    params
        The live PX4 parameter set (defaults when omitted).
    log
        Where estimates and set-points go (``None``: no log).
    """

    def __init__(self, params: Parameters | None = None, log: ULogWriter | None = None) -> None:
        self.params = params or Parameters()
        self.log = log
        self.attitude = AttitudeEstimator()
        self.position = PositionEstimator()
        self.ground = DistanceToGround()
        self.flow = OpticalFlowFusion()
        self.gyro_calibration = GyroRestCalibration()
        self.rate_control = RateController(self.params)
        self.attitude_control = AttitudeController(self.params)
        self.position_control = PositionController(self.params)
        self.allocator = ControlAllocator(self.params)
        self.navigator = Navigator(
            self.params, self._to_local, self._on_item_reached, self._on_mission_current
        )
        self.monitors = {
            "accel": SensorMonitor("Accel", self.params["COM_IMU_LOSS_T"]),
            "gyro": SensorMonitor("Gyro", self.params["COM_IMU_LOSS_T"]),
            "mag": SensorMonitor("Compass", _SENSOR_TIMEOUT_S),
            "baro": SensorMonitor("Barometer", _SENSOR_TIMEOUT_S),
            "gps": SensorMonitor("GPS", self.params["COM_POS_FS_DELAY"]),
        }
        self.status_messages: deque[tuple[int, str]] = deque(maxlen=64)
        self.mission_events: deque[tuple[str, int]] = deque(maxlen=256)
        self.armed = False
        self.armed_time_us = 0
        self.nav_state = NavState.AUTO_LOITER
        self.user_nav_state = NavState.AUTO_LOITER
        self.failsafe = False
        self.land_detector = LandDetector()
        self.manual = ManualTask(self.params)
        #: The pilot's sticks as last received (MANUAL_CONTROL), None before any.
        self.sticks: Sticks | None = None
        self.time_us = 0
        self.home: tuple[float, float, float] | None = None  # lat, lon, alt AMSL
        self.motors = self._stopped()
        self.torque_sp = np.zeros(3)
        self.thrust_sp_ned = np.zeros(3)
        self.collective_thrust = 0.0
        self.rates_sp = np.zeros(3)
        self.q_sp = np.array([1.0, 0.0, 0.0, 0.0])
        self.setpoint: Setpoint | None = None
        self.velocity_sp = np.zeros(3)
        self.acceleration_sp = np.zeros(3)
        self.truth: GroundTruth | None = None
        self._gps_good = False
        self._params_version = -1
        self._rates_filter = AngularVelocityFilter(self.params)
        self._imu_frames = 0
        self._last_position_loop_us = -POSITION_LOOP_PERIOD_US
        self._last_fast_log_us = -FAST_LOG_PERIOD_US
        self._last_slow_log_us = -POSITION_LOOP_PERIOD_US
        self._took_off = False
        self._landed_since_us = 0
        self._offboard_sp_time_us: int | None = None
        self._reported_faults: set[str] = set()
        self._use_gps_height = False
        self._takeoff_altitude_amsl_m = math.nan  # NaN: MIS_TAKEOFF_ALT above home
        self._gps_velocity: tuple[NDArray[np.float64], int] | None = None
        self._gps_accel_ned = np.zeros(3)
        self._last_mag_gauss: NDArray[np.float64] | None = None
        self._offboard_body: BodySetpoint | None = None
        self._imu_average: ImuAverage | None = None
        #: The frame's gyro and accelerometer sample (:meth:`step`), until :meth:`write_log`.
        self._imu_sample: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
        self._motor_test: tuple[int, float, int] | None = None  # motor, throttle, end time

    # ------------------------------------------------------------------ frame
    def update(self, sensors: SensorFrame, time_us: int) -> Controls:
        """Run one frame at sensor time ``time_us`` and return the motor commands, logged
        (:meth:`step`, then :meth:`write_log`)."""
        controls = self.step(sensors, time_us)
        self.write_log(time_us)
        return controls

    def step(self, sensors: SensorFrame, time_us: int) -> Controls:
        """Run one frame at sensor time ``time_us`` and return the motor commands; the frame's
        log waits for :meth:`write_log`, so the process can answer the simulator first (as
        PX4's logger writes from a thread of its own, off the control path)."""
        dt_s = min(max((time_us - self.time_us) * 1e-6, 1e-4), 0.02) if self.time_us else 1e-3
        self.time_us = time_us
        if self._params_version != self.params.version:
            self._configure()
        self._sample_monitors(sensors, time_us)
        gyro, accel = sensors.gyro_radps, sensors.accel_mps2
        if accel is not None and gyro is not None:
            self._imu_sample = (gyro, accel)  # averaged for the log by write_log
            self._estimate(sensors, gyro, accel, dt_s, time_us)
        self._commander(time_us)
        if self.armed and self._imu_frames:
            self._control(dt_s, time_us)
        else:
            self.motors = self._stopped()
            self.rate_control.reset_integral()
            self.position_control.reset_integral()
        if self._motor_test is not None and not self.armed:
            motor, throttle, end_us = self._motor_test
            if time_us < end_us:
                # PX4's actuator test drives the output while disarmed; the armed bit tells the
                # rig that this output is live.
                motors = self._stopped()
                motors[motor] = throttle
                return Controls(tuple(motors.tolist()), True)
            self._motor_test = None
        return Controls(tuple(self.motors.tolist()), self.armed)

    def _stopped(self) -> NDArray[np.float64]:
        """Every motor of the airframe (``CA_ROTOR_COUNT``) at zero."""
        return np.zeros(self.allocator.motor_count)

    def observe_truth(self, truth: GroundTruth) -> None:
        """Ground truth from the simulator: kept only to log the estimator's errors."""
        self.truth = truth

    # ------------------------------------------------------------------ commands
    def arm(self, force: bool = False) -> CommandResult:
        if self.armed:
            return _ACCEPTED
        if self.nav_state in (NavState.AUTO_LAND, NavState.DESCEND, NavState.TERMINATION):
            return self.refuse(f"Arming denied: not possible in {self.nav_state.name} mode")
        if not force:
            reason = self.preflight_failure()
            if reason:
                return self.refuse(reason)
        if self.nav_state == NavState.OFFBOARD and not self._offboard_fresh():
            return self.refuse("Arming denied: no offboard setpoint")
        if self.nav_state in _STICK_MODES and not self.sticks_present():
            return self.refuse("Arming denied: no manual control input")
        self.armed = True
        self._took_off = False
        self.gyro_calibration.reset()
        self.armed_time_us = self.time_us
        self.land_detector.arm(float(self.position.position_ned_m[2]))
        self._landed_since_us = self.time_us
        self._set_home()
        self._enter(self.nav_state)
        if self.nav_state == NavState.AUTO_TAKEOFF:
            self._prepare_takeoff()
        self.notify(mavlink.MAV_SEVERITY_INFO, "Armed by external command")
        return _ACCEPTED

    def disarm(self, force: bool = False) -> CommandResult:
        if not self.armed:
            return _ACCEPTED
        if not self.landed and not force:
            return self.refuse("Disarming denied: not landed")
        self._disarm("Disarmed by external command")
        return _ACCEPTED

    def set_mode(self, nav_state: NavState) -> CommandResult:
        """Switch modes as PX4's commander does: refused when the mode cannot run."""
        if nav_state in _POSITION_MODES and not self.position_valid():
            return self.refuse(f"Switching to {nav_state.name} denied: no position estimate")
        if nav_state == NavState.AUTO_MISSION and not self.navigator.mission:
            return self.refuse("Switching to mission denied: no valid mission")
        if nav_state == NavState.AUTO_MISSION and self.position.origin is None:
            return self.refuse("Switching to mission denied: no global position (GPS)")
        if nav_state == NavState.OFFBOARD and not self._offboard_fresh():
            return self.refuse("Switching to offboard denied: no offboard setpoint")
        if nav_state == NavState.ALTCTL and not self.height_valid():
            return self.refuse("Switching to ALTCTL denied: no height estimate")
        if nav_state in _STICK_MODES and not self.sticks_present():
            return self.refuse(f"Switching to {nav_state.name} denied: no manual control input")
        self.user_nav_state = nav_state
        self.failsafe = False
        self._enter(nav_state)
        self._takeoff_altitude_amsl_m = math.nan
        if nav_state == NavState.AUTO_TAKEOFF and self.armed:
            self._prepare_takeoff()
        if nav_state == NavState.AUTO_MISSION and self.navigator.mission_finished:
            self.navigator.set_mission_current(0)
        return _ACCEPTED

    def takeoff(self, altitude_amsl_m: float) -> CommandResult:
        """NAV_TAKEOFF: climb to ``altitude_amsl_m`` (NaN: MIS_TAKEOFF_ALT above home)."""
        if math.isfinite(altitude_amsl_m) and self.position.origin is None:
            return self.refuse("Takeoff denied: an altitude AMSL needs a global position")
        result = self.set_mode(NavState.AUTO_TAKEOFF)
        if result.result != mavlink.MAV_RESULT_ACCEPTED:
            return result
        self._takeoff_altitude_amsl_m = altitude_amsl_m
        if self.armed:
            self._prepare_takeoff()
        return result

    def land(self) -> CommandResult:
        return self.set_mode(NavState.AUTO_LAND)

    def set_mission(self, items: list[MissionItem]) -> None:
        self.navigator.set_mission(items)
        self.notify(mavlink.MAV_SEVERITY_INFO, f"Mission with {len(items)} items uploaded")

    def set_mission_current(self, seq: int) -> bool:
        if not 0 <= seq < len(self.navigator.mission):
            return False
        self.navigator.set_mission_current(seq)
        self.mission_events.append(("current", seq))
        return True

    def set_offboard_setpoint(
        self,
        position_ned_m: NDArray[np.float64],
        velocity_ned_mps: NDArray[np.float64],
        yaw_rad: float,
        yawspeed_radps: float,
    ) -> None:
        """SET_POSITION_TARGET_LOCAL_NED: NaN entries are not controlled."""
        nav = self.navigator
        nav.offboard_position = np.asarray(position_ned_m, dtype=float)
        nav.offboard_velocity = np.asarray(velocity_ned_mps, dtype=float)
        nav.offboard_yaw_rad, nav.offboard_yawspeed_radps = yaw_rad, yawspeed_radps
        self._offboard_body = None
        self._offboard_sp_time_us = self.time_us

    def set_sticks(self, sticks: Sticks) -> None:
        """MANUAL_CONTROL: the pilot's sticks, used by Position and Altitude modes."""
        self.sticks = sticks

    def set_offboard_attitude(self, q: NDArray[np.float64], thrust: float) -> None:
        """SET_ATTITUDE_TARGET: attitude and collective thrust 0..1, position control off."""
        thrust = min(max(thrust, 0.0), 1.0)
        self._offboard_body = BodySetpoint(np.asarray(q, dtype=float), None, thrust)
        self._offboard_sp_time_us = self.time_us

    def set_offboard_rates(self, rates_radps: NDArray[np.float64], thrust: float) -> None:
        """SET_ATTITUDE_TARGET with the attitude ignored: body rates (FRD) and collective
        thrust 0..1 straight to the rate loop, as PX4 publishes vehicle_rates_setpoint."""
        thrust = min(max(thrust, 0.0), 1.0)
        self._offboard_body = BodySetpoint(None, np.asarray(rates_radps, dtype=float), thrust)
        self._offboard_sp_time_us = self.time_us

    def motor_test(self, motor: int, throttle: float, duration_s: float) -> CommandResult:
        """DO_MOTOR_TEST: spin one motor while disarmed on the ground (PX4 actuator test)."""
        if self.armed or not self.landed:
            return self.refuse("Motor test denied: vehicle armed")
        motors = self.allocator.motor_count
        if not 0 <= motor < motors or not 0.0 <= throttle <= 1.0 or not 0.0 < duration_s <= 60.0:
            return self.refuse(f"Motor test denied: motor {motor + 1} at {throttle:.0%} "
                                f"for {duration_s:g} s is out of range")  # fmt: skip
        self._motor_test = (motor, throttle, self.time_us + int(duration_s * 1e6))
        return _ACCEPTED

    def set_parameter(self, name: str, value: float) -> float | int:
        """Set a parameter (raises :class:`ParameterError`); logged as PX4 logs ``param set``."""
        stored = self.params.set(name, value)
        if self.log is not None:
            self.log.set_parameter(name, stored)
        return stored

    # ------------------------------------------------------------------ state queries
    @property
    def landed(self) -> bool:
        return self.land_detector.landed

    def position_valid(self) -> bool:
        """PX4's local position ``xy_valid``: a horizontal aid (GPS, optical flow) is fused."""
        return (self.position.origin is not None and self._gps_good) or self.flow.aiding(
            self.time_us
        )

    def height_valid(self) -> bool:
        """PX4's local position ``z_valid``: a height aid (barometer, GPS, rangefinder) works."""
        t = self.time_us
        return self.monitors["baro"].healthy(t) or self._gps_good or self.ground.valid(t)

    def sticks_present(self) -> bool:
        """Sticks heard within COM_RC_LOSS_T (PX4's ``manual_control_signal_lost`` false)."""
        sticks = self.sticks
        return sticks is not None and (
            self.time_us - sticks.time_us <= self.params["COM_RC_LOSS_T"] * 1e6
        )

    def attitude_valid(self) -> bool:
        return self.attitude.initialized and self.monitors["gyro"].healthy(self.time_us)

    def preflight_failure(self) -> str | None:
        """The first failing pre-arm check, worded as PX4's commander words it."""
        t = self.time_us
        required = ["accel", "gyro"]
        if self.params["SYS_HAS_MAG"]:
            required.append("mag")
        if self.params["SYS_HAS_BARO"]:
            required.append("baro")
        for key in required:
            fault = self.monitors[key].fault(t)
            if fault:
                return f"Preflight Fail: {self.monitors[key].name} Sensor 0 {fault}"
        flow = self.flow.aiding(t)  # then GPS is not needed, nor a global position
        if not flow and self.monitors["gps"].fault(t):
            return f"Preflight Fail: GPS {self.monitors['gps'].fault(t)}"
        if not flow and not self._gps_good:
            return "Preflight Fail: GPS fix too low"
        if not self.attitude.initialized:
            return "Preflight Fail: attitude estimate not valid"
        if not flow and self.position.origin is None:
            return "Preflight Fail: no valid global position"
        return None

    def global_position(self) -> tuple[float, float, float]:
        """Latitude, longitude (deg) and altitude AMSL (m) of the estimate."""
        if self.position.origin is None:
            return (math.nan, math.nan, math.nan)
        lat0, lon0, alt0 = self.position.origin
        return ned_to_geodetic(self.position.position_ned_m, lat0, lon0, alt0)

    def landed_state(self) -> int:
        """MAV_LANDED_STATE for EXTENDED_SYS_STATE."""
        if self.landed:
            return mavlink.MAV_LANDED_STATE_ON_GROUND
        if self.nav_state == NavState.AUTO_TAKEOFF:
            return mavlink.MAV_LANDED_STATE_TAKEOFF
        if self.nav_state in (NavState.AUTO_LAND, NavState.DESCEND):
            return mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAV_LANDED_STATE_IN_AIR

    # ------------------------------------------------------------------ internals
    def _configure(self) -> None:
        p = self.params
        self.attitude.configure(p)
        self.position.configure(p)
        self.ground.configure(p)
        self.flow.configure(p)
        self.rate_control.configure(p)
        self.attitude_control.configure(p)
        self.position_control.configure(p)
        self.allocator.configure(p)
        if not p["ATT_MAG_DECL_A"]:
            self.attitude.set_declination(math.radians(p["ATT_MAG_DECL"]))
        self._rates_filter.configure(p)
        if self._imu_average is None or self._imu_average.rate_hz != p["IMU_INTEG_RATE"]:
            self._imu_average = ImuAverage(p["IMU_INTEG_RATE"])
        self._params_version = p.version

    def _sample_monitors(self, sensors: SensorFrame, time_us: int) -> None:
        m = self.monitors
        if sensors.accel_mps2 is not None:
            m["accel"].sample(sensors.accel_mps2, time_us)
        if sensors.gyro_radps is not None:
            m["gyro"].sample(sensors.gyro_radps, time_us)
        if sensors.mag_gauss is not None:
            m["mag"].sample(sensors.mag_gauss, time_us)
        if sensors.baro_pressure_pa is not None:
            m["baro"].sample(sensors.baro_pressure_pa, time_us)
        if sensors.gps is not None:
            m["gps"].sample(sensors.gps, time_us)

    def _estimate(
        self,
        sensors: SensorFrame,
        gyro: NDArray[np.float64],
        accel: NDArray[np.float64],
        dt_s: float,
        time_us: int,
    ) -> None:
        """The estimators' frame: ``gyro`` and ``accel`` are ``sensors``' IMU sample."""
        if sensors.mag_gauss is not None:
            self._last_mag_gauss = sensors.mag_gauss
        # the latest field is used every frame, as PX4's filter keeps it between samples
        mag = self._last_mag_gauss if self.monitors["mag"].healthy(time_us) else None
        if mag is None and self.params["SYS_HAS_MAG"] and not self.attitude.initialized:
            # PX4's attitude_estimator_q initializes only once it has a field sample (its
            # init_attq takes north from the magnetometer): the first IMU frames come before
            # the first mag sample, and north from nothing would start the heading at 0 and
            # take tens of seconds to converge on a vehicle that does not face north.
            return
        self._imu_frames += 1
        compensation = None
        if self.params["ATT_ACC_COMP"] and self.monitors["gps"].healthy(time_us):
            compensation = self._gps_accel_ned
        if not self.armed:
            offsets = self.gyro_calibration.update(gyro, accel, dt_s)
            if offsets is not None:
                self.attitude.gyro_bias_radps = offsets
        self.attitude.update(gyro, accel, mag, dt_s, compensation)
        self.flow.add_gyro(time_us, self.attitude.rates_radps, dt_s)
        self._rates_filter.update(self.attitude.rates_radps, time_us)
        if sensors.range is not None:
            self._fuse_range(sensors.range, time_us)
        self.position.predict(quat_to_dcm(self.attitude.q) @ accel, dt_s)
        baro_ok = self.monitors["baro"].healthy(time_us)
        if sensors.baro_pressure_pa is not None and baro_ok:
            learn_bias = self.position.gps_height_reference and self._gps_good
            self.position.fuse_baro(pressure_altitude_m(sensors.baro_pressure_pa), learn_bias)
        self._use_gps_height = not baro_ok or self.position.gps_height_reference
        if sensors.flow is not None:
            gps_aid = self.position.origin is not None and self._gps_good
            height = self.ground.height(time_us)
            previous = self.flow.sample
            self.flow.update(sensors.flow, self.position, self.attitude.q, height,
                             not self.landed, gps_aid, time_us)  # fmt: skip
            sample = self.flow.sample
            if sample is not None and sample is not previous and self.log is not None:
                self._log_flow(self.log, sample, time_us)
        gps = sensors.gps
        gps_ctrl = int(self.params["EKF2_GPS_CTRL"])
        if not gps_ctrl & 0b101:  # neither its position nor its velocity is used
            self._gps_good = False
            return
        if gps is None:
            self._gps_good = self._gps_good and self.monitors["gps"].healthy(time_us)
            return
        self._gps_good = (
            gps.fix_type >= 3
            and gps.satellites_used >= self.params["EKF2_REQ_NSATS"]
            and gps.eph_m <= self.params["EKF2_REQ_EPH"]
            and self.monitors["gps"].healthy(time_us)
        )
        if not self._gps_good:
            return
        velocity = np.array(gps.velocity_ned_mps)
        self._update_gps_acceleration(velocity, time_us)
        if self.position.origin is None:
            self.position.set_origin(gps.lat_deg, gps.lon_deg, gps.alt_amsl_m, time_us, velocity)
            if self.params["ATT_MAG_DECL_A"]:
                self.attitude.set_declination(_wmm_declination_rad(gps.lat_deg, gps.lon_deg))
            return
        local = self._to_local(gps.lat_deg, gps.lon_deg, gps.alt_amsl_m)
        self.position.fuse_gps(
            local, velocity, use_height=self._use_gps_height and bool(gps_ctrl & 0b010),
            use_position=bool(gps_ctrl & 0b001), use_velocity=bool(gps_ctrl & 0b100),
        )  # fmt: skip

    def _fuse_range(self, reading: RangeReading, time_us: int) -> None:
        """The rangefinder: height above the ground, and the height aid near it (PX4
        ``EKF2_RNG_CTRL``: 1 below ``EKF2_RNG_A_HMAX`` and slower than ``EKF2_RNG_A_VMAX``
        horizontally, 2 always)."""
        ground, p = self.ground, self.params
        limits = (reading.min_m, reading.max_m)
        if not ground.update(reading.distance_m, reading.signal_quality, limits,
                             self.attitude.q, time_us):  # fmt: skip
            return
        mode = p["EKF2_RNG_CTRL"]
        velocity = self.position.velocity_ned_mps
        aid = mode == 2 or (
            mode == 1
            and ground.height_m < p["EKF2_RNG_A_HMAX"]
            and math.hypot(velocity[0], velocity[1]) < p["EKF2_RNG_A_VMAX"]
        )
        self.position.fuse_range(ground.height_m, aid)

    def _update_gps_acceleration(self, velocity: NDArray[np.float64], time_us: int) -> None:
        """Acceleration from successive GPS velocities, low-passed, for the attitude filter's
        compensation. It must not come from the position filter: that one integrates the
        accelerometer through the attitude estimate, and would cancel the very tilt error the
        compensation is meant to expose (PX4 attitude_estimator_q also differences GPS)."""
        previous, self._gps_velocity = self._gps_velocity, (velocity, time_us)
        if previous is None or time_us <= previous[1]:
            return
        dt_s = (time_us - previous[1]) * 1e-6
        if dt_s > 1.0:  # a gap: start again
            self._gps_accel_ned = np.zeros(3)
            return
        raw = (velocity - previous[0]) / dt_s
        alpha = dt_s / (_GPS_ACCEL_TAU_S + dt_s)
        self._gps_accel_ned = self._gps_accel_ned + alpha * (raw - self._gps_accel_ned)

    def _commander(self, time_us: int) -> None:
        self._report_sensor_faults(time_us)
        if not self.armed:
            # As PX4's commander: home is set once the global position is valid (ground
            # stations and MAVSDK wait for it before arming), and again at arming.
            if self.home is None and self.position_valid():
                self._set_home()
            return
        imu_fault = self.monitors["gyro"].fault(time_us) or self.monitors["accel"].fault(time_us)
        if imu_fault:
            self.nav_state = NavState.TERMINATION
            self.failsafe = True
            self._disarm(f"Failsafe: IMU {imu_fault}, motors off")
            return
        if self.nav_state in _POSITION_MODES and not self.position_valid():
            # PX4: no local position, so neither Hold nor Land can run; Position mode falls
            # back to Altitude while a pilot is on the sticks; Descend needs only the height
            self.failsafe = True
            lost = "optical flow" if self.flow.active else "GPS"
            fallback = NavState.DESCEND
            if self.nav_state == NavState.POSCTL and self.height_valid() and self.sticks_present():
                fallback = NavState.ALTCTL
            self._enter(fallback)
            name = "Altitude" if fallback == NavState.ALTCTL else "Descend"
            text = f"Failsafe: no position ({lost} lost), {name}"
            self.notify(mavlink.MAV_SEVERITY_CRITICAL, text)
        if self.nav_state == NavState.ALTCTL and not self.height_valid():
            self.failsafe = True
            self._enter(NavState.DESCEND)
            self.notify(mavlink.MAV_SEVERITY_CRITICAL, "Failsafe: no height estimate, Descend")
        if self.nav_state in _STICK_MODES and not self.sticks_present():
            # PX4's NAV_RCL_ACT: Return, or Land without one, or Descend without a position
            self.failsafe = True
            land = self.position_valid()
            self._enter(NavState.AUTO_LAND if land else NavState.DESCEND)
            text = f"Failsafe: manual control lost, {'Land' if land else 'Descend'}"
            self.notify(mavlink.MAV_SEVERITY_CRITICAL, text)
        if self.nav_state == NavState.OFFBOARD and not self._offboard_fresh():
            self.failsafe = True
            self._enter(NavState.AUTO_LOITER)
            self.notify(mavlink.MAV_SEVERITY_CRITICAL, "Failsafe: offboard signal lost, Hold")
        self._land_detector(time_us)

    def _set_home(self) -> None:
        lat, lon, alt = self.global_position()
        self.home = (lat, lon, alt)
        self.navigator.home_ned = self.position.position_ned_m.copy()
        self.navigator.home_alt_amsl_m = alt

    def _report_sensor_faults(self, time_us: int) -> None:
        """One status text per sensor that goes bad after having worked."""
        for key, monitor in self.monitors.items():
            fault = monitor.fault(time_us) if monitor.last_time_us is not None else None
            if fault and key not in self._reported_faults:
                self._reported_faults.add(key)
                self.notify(mavlink.MAV_SEVERITY_CRITICAL, f"{monitor.name} sensor {fault}")
            elif not fault:
                self._reported_faults.discard(key)

    def _land_detector(self, time_us: int) -> None:
        p, detector = self.params, self.land_detector
        down_m = float(self.position.position_ned_m[2])
        velocity = self.position.velocity_ned_mps
        if detector.landed:
            idle = self._idle()
            if not idle and detector.detect_takeoff(down_m, float(velocity[2])):
                self._took_off = True
                self.notify(mavlink.MAV_SEVERITY_INFO, "Takeoff detected")
            elif idle and not self._took_off:
                limit_s = p["COM_DISARM_PRFLT"]
                if limit_s > 0 and time_us - self.armed_time_us > limit_s * 1e6:
                    self._disarm("Disarmed: no takeoff (COM_DISARM_PRFLT)")
            elif idle:
                limit_s = p["COM_DISARM_LAND"]
                if limit_s >= 0 and time_us - self._landed_since_us > limit_s * 1e6:
                    self._disarm("Disarmed: landed (COM_DISARM_LAND)")
            return
        rates = self._rates_filter.rates_radps
        if detector.detect_landing(
            p, time_us, float(velocity[2]),
            math.hypot(velocity[0], velocity[1]) if self.position_valid() else None,
            float(self.velocity_sp[2]), self.collective_thrust, math.hypot(rates[0], rates[1]),
            self.ground.height(time_us),
        ):  # fmt: skip
            self._landed_since_us = time_us
            self.notify(mavlink.MAV_SEVERITY_INFO, "Landing detected")
            if self.nav_state == NavState.AUTO_MISSION:
                self.navigator.land_item_done()

    def _idle(self) -> bool:
        """On the ground with nothing asking to climb: motors at idle."""
        if not self.landed:
            return False
        if self.time_us - self.armed_time_us < self.params["COM_SPOOLUP_TIME"] * 1e6:
            return True
        if self.nav_state == NavState.AUTO_TAKEOFF:
            return False
        if self.nav_state in _STICK_MODES:
            return self.sticks is None or not self.manual.wants_takeoff(self.sticks)
        if self.nav_state == NavState.AUTO_MISSION:
            return self.navigator.mission_finished
        if self.nav_state == NavState.OFFBOARD:
            if self._offboard_body is not None:
                return self._offboard_body.thrust <= self.params["MPC_THR_MIN"]
            nav = self.navigator
            z = self.position.position_ned_m[2]
            return not (nav.offboard_position[2] < z - 0.3 or nav.offboard_velocity[2] < -0.1)
        return True

    def _control(self, dt_s: float, time_us: int) -> None:
        q = self.attitude.q
        if time_us - self._last_position_loop_us >= POSITION_LOOP_PERIOD_US:
            position_dt = min((time_us - self._last_position_loop_us) * 1e-6, 0.1)
            self._last_position_loop_us = time_us
            self._position_loop(position_dt, time_us)
        if self._idle():
            self.motors = self._stopped()
            self.rate_control.reset_integral()
            return
        # PX4's attitude and rate controllers take an offboard setpoint on their next cycle,
        # not on the 50 Hz position loop's
        body = self._offboard_body if self.nav_state == NavState.OFFBOARD else None
        if body is not None:
            self.collective_thrust = body.thrust
            self.q_sp = body.q if body.q is not None else self.q_sp
        if body is not None and body.rates_radps is not None:
            self.rates_sp = body.rates_radps  # the rate loop only
        else:
            yaw_feed_forward = self.setpoint.yawspeed_radps if self.setpoint else 0.0
            self.rates_sp = self.attitude_control.update(q, self.q_sp, yaw_feed_forward)
        rates = self._rates_filter
        # The integral holds from the land detector's second stage on, as PX4's
        # MulticopterRateControl passes it `_maybe_landed || _landed`: on the ground the rate
        # errors are the ground's doing, and integrating them tilts the motors apart.
        on_ground = self.landed or self.land_detector.maybe_landed
        self.torque_sp = self.rate_control.update(
            rates.rates_radps, self.rates_sp, rates.angular_accel_radps2, dt_s, on_ground
        )
        self.motors = self.allocator.allocate(self.torque_sp, self.collective_thrust)
        unallocated = self.allocator.unallocated[:3]
        self.rate_control.saturated_positive = unallocated > 1e-6
        self.rate_control.saturated_negative = unallocated < -1e-6

    def _position_loop(self, dt_s: float, time_us: int) -> None:
        est = self.position
        position = est.position_ned_m
        nav = self.navigator
        nav.vehicle_ned = position
        dist_bottom = self.ground.height(time_us)
        if self._idle():
            self.setpoint = None
            self.position_control.reset_integral()
            nav.enter(position, np.zeros(3), float(euler_from_quat(self.attitude.q)[2]))
            if self.nav_state in _STICK_MODES:  # PX4: ready for take-off, the ramp from 0
                self.manual.activate(position, self.nav_state == NavState.POSCTL, on_ground=True)
            self.collective_thrust = 0.0
            return
        if self.nav_state == NavState.AUTO_TAKEOFF:
            setpoint = nav.takeoff(dt_s)
            if abs(position[2] - nav.takeoff_target_ned[2]) < self.params["NAV_MC_ALT_RAD"]:
                self.notify(mavlink.MAV_SEVERITY_INFO, "Takeoff complete, holding")
                nav.hold_ned = nav.takeoff_target_ned.copy()
                self.nav_state = self.user_nav_state = NavState.AUTO_LOITER
        elif self.nav_state == NavState.AUTO_MISSION:
            step = nav.mission_step(position, self.landed, time_us, dt_s)
            setpoint = nav.land(position, dt_s, dist_bottom) if step == "land" else step
        elif self.nav_state == NavState.AUTO_LAND:
            setpoint = nav.land(position, dt_s, dist_bottom)
        elif self.nav_state == NavState.DESCEND:
            setpoint = nav.descend()
        elif self.nav_state == NavState.OFFBOARD and self._offboard_body is not None:
            self.setpoint = None
            self.position_control.reset_integral()
            return  # _control applies the body setpoint every frame
        elif self.nav_state == NavState.OFFBOARD:
            setpoint = nav.offboard()
        elif self.nav_state in _STICK_MODES and self.sticks is not None:
            height = nav.home_ned[2] - position[2] if dist_bottom is None else dist_bottom
            yaw = float(euler_from_quat(self.attitude.q)[2])
            setpoint = self.manual.update(self.sticks, position, est.velocity_ned_mps, yaw,
                                          height, dt_s)  # fmt: skip
        else:
            setpoint = nav.hold(dt_s)
        self.setpoint = setpoint
        if self.land_detector.ground_contact:
            # PX4 mc_pos_control, "flying but ground contact": no corrections, minimum
            # thrust, integrators reset, so the land detector can confirm the touchdown
            self.position_control.reset_integral()
            self.thrust_sp_ned = np.array([0.0, 0.0, -self.position_control.thrust_min])
            yaw = float(euler_from_quat(self.attitude.q)[2])
            self.q_sp, self.collective_thrust = thrust_to_attitude(self.thrust_sp_ned, yaw)
            return
        thrust, self.velocity_sp, self.acceleration_sp = self.position_control.update(
            position,
            est.velocity_ned_mps,
            setpoint.position_ned_m,
            setpoint.velocity_ned_mps,
            setpoint.velocity_limits_mps,
            dt_s,
            acceleration_sp=setpoint.acceleration_ned_mps2,
        )
        self.thrust_sp_ned = thrust
        self.q_sp, self.collective_thrust = thrust_to_attitude(thrust, setpoint.yaw_rad)

    def _enter(self, nav_state: NavState) -> None:
        self.nav_state = nav_state
        est = self.position
        self.navigator.enter(
            est.position_ned_m, est.velocity_ned_mps, float(euler_from_quat(self.attitude.q)[2])
        )
        if nav_state in _STICK_MODES:
            self.manual.activate(est.position_ned_m, nav_state == NavState.POSCTL, self.landed)

    def _prepare_takeoff(self) -> None:
        """Climb from here to the requested altitude, at least MIS_TAKEOFF_ALT above home
        when none was given (PX4 takeoff)."""
        altitude = self._takeoff_altitude_amsl_m
        nav = self.navigator
        above_home_m = (altitude - nav.home_alt_amsl_m if math.isfinite(altitude)
                        else self.params["MIS_TAKEOFF_ALT"])  # fmt: skip
        nav.set_takeoff_target(self.position.position_ned_m, above_home_m)

    def _offboard_fresh(self) -> bool:
        last = self._offboard_sp_time_us
        return last is not None and self.time_us - last <= self.params["COM_OF_LOSS_T"] * 1e6

    def _disarm(self, reason: str) -> None:
        self.armed = False
        self.land_detector.disarm()
        self.motors = self._stopped()
        severity = mavlink.MAV_SEVERITY_CRITICAL if self.failsafe else mavlink.MAV_SEVERITY_INFO
        self.notify(severity, reason)

    def refuse(self, reason: str) -> CommandResult:
        """Refuse a request: the reason goes out as a critical STATUSTEXT and into the log."""
        self.notify(mavlink.MAV_SEVERITY_CRITICAL, reason)
        return CommandResult(mavlink.MAV_RESULT_TEMPORARILY_REJECTED, reason)

    def notify(self, severity: int, text: str) -> None:
        """Tell the ground stations (STATUSTEXT) and the log, as PX4's ``mavlink_log_*``."""
        self.status_messages.append((severity, text))
        if self.log is not None:
            self.log.log(_SEVERITY_LEVEL.get(severity, "info"), self.time_us, text)

    def _to_local(self, lat_deg: float, lon_deg: float, alt_amsl_m: float) -> NDArray[np.float64]:
        assert self.position.origin is not None, "set at the first good GPS fix"
        lat0, lon0, alt0 = self.position.origin
        return geodetic_to_ned(lat_deg, lon_deg, alt_amsl_m, lat0, lon0, alt0)

    def _on_item_reached(self, seq: int) -> None:
        self.mission_events.append(("reached", seq))
        self.notify(mavlink.MAV_SEVERITY_INFO, f"Mission item {seq} reached")

    def _on_mission_current(self, seq: int) -> None:
        self.mission_events.append(("current", seq))

    # ------------------------------------------------------------------ log
    def _log_imu_average(
        self, gyro: NDArray[np.float64], accel: NDArray[np.float64], time_us: int
    ) -> None:
        """``sensor_combined`` as PX4 logs it: the raw IMU averaged per IMU_INTEG_RATE."""
        assert self._imu_average is not None, "_configure sets it"
        interval = self._imu_average.add(time_us, gyro, accel)
        if interval is None or self.log is None:
            return
        self.log.write(
            "sensor_combined", time_us, gyro_rad=interval.gyro_radps,
            gyro_integral_dt=interval.integral_dt_us, accelerometer_timestamp_relative=0,
            accelerometer_m_s2=interval.accel_mps2,
            accelerometer_integral_dt=interval.integral_dt_us, accelerometer_clipping=0,
            gyro_clipping=0,
        )  # fmt: skip

    @staticmethod
    def _log_flow(log: ULogWriter, sample: FlowVelocity, time_us: int) -> None:
        """``estimator_optical_flow_vel`` for a flow sample used, as EKF2 publishes it."""
        log.write(
            "estimator_optical_flow_vel", time_us, timestamp_sample=sample.time_us,
            vel_body=sample.velocity_body_mps, vel_ne=sample.velocity_ne_mps,
            flow_uncompensated_integral=sample.flow_rad,
            flow_compensated_integral=sample.compensated_rad,
            gyro_rate=sample.gyro_rad / sample.dt_s, gyro_rate_integral=sample.gyro_rad,
        )  # fmt: skip

    def write_log(self, time_us: int) -> None:
        """Log the frame :meth:`step` ran at ``time_us`` (the topics due at that time); to
        follow every step, as its IMU sample counts in ``sensor_combined``'s average."""
        if self._imu_sample is not None:
            self._log_imu_average(*self._imu_sample, time_us)
            self._imu_sample = None
        log = self.log
        if log is None or not self._imu_frames:
            return
        if time_us - self._last_fast_log_us >= FAST_LOG_PERIOD_US:
            self._last_fast_log_us = time_us
            rates = self._rates_filter
            log.write("vehicle_attitude", time_us, timestamp_sample=time_us, q=self.attitude.q,
                      delta_q_reset=np.zeros(4), quat_reset_counter=0)  # fmt: skip
            log.write("vehicle_angular_velocity", time_us, timestamp_sample=time_us,
                      xyz=rates.rates_radps, xyz_derivative=rates.angular_accel_radps2)  # fmt: skip
            thrust_body = np.array([0.0, 0.0, -self.collective_thrust])
            rates_sp = self.rates_sp
            log.write("vehicle_rates_setpoint", time_us, roll=rates_sp[0],
                      pitch=rates_sp[1], yaw=rates_sp[2], thrust_body=thrust_body)  # fmt: skip
            log.write("vehicle_torque_setpoint", time_us, timestamp_sample=time_us,
                      xyz=self.torque_sp)  # fmt: skip
            log.write("vehicle_thrust_setpoint", time_us, timestamp_sample=time_us,
                      xyz=thrust_body)  # fmt: skip
            control = np.full(12, np.nan)
            control[: self.motors.size] = self.motors if self.armed else np.nan
            log.write("actuator_motors", time_us, timestamp_sample=time_us, reversible_flags=0,
                      control=control)  # fmt: skip
        if time_us - self._last_slow_log_us >= POSITION_LOOP_PERIOD_US:
            self._last_slow_log_us = time_us
            self._write_slow_log(log, time_us)

    def _write_slow_log(self, log: ULogWriter, time_us: int) -> None:
        est = self.position
        p, v, a = est.position_ned_m, est.velocity_ned_mps, est.accel_ned_mps2
        origin = est.origin or (math.nan, math.nan, math.nan)
        pos_std, vel_std = est.position_std_m, est.velocity_std_mps
        valid = self.position_valid()
        log.write(
            "vehicle_local_position", time_us, timestamp_sample=time_us, xy_valid=valid,
            z_valid=True, v_xy_valid=valid, v_z_valid=True, x=p[0], y=p[1], z=p[2], vx=v[0],
            vy=v[1], vz=v[2], z_deriv=v[2], ax=a[0], ay=a[1], az=a[2],
            heading=float(euler_from_quat(self.attitude.q)[2]), xy_global=est.origin is not None,
            z_global=est.origin is not None, ref_lat=origin[0], ref_lon=origin[1],
            ref_alt=origin[2], eph=math.hypot(pos_std[0], pos_std[1]), epv=pos_std[2],
            evh=math.hypot(vel_std[0], vel_std[1]), evv=vel_std[2],
            dead_reckoning=not valid, dist_bottom=self.ground.height_m,
            dist_bottom_valid=self.ground.valid(time_us),
        )  # fmt: skip
        thrust_body = np.array([0.0, 0.0, -self.collective_thrust])
        sp = self.setpoint
        yaw_rate = sp.yawspeed_radps if sp else 0.0
        log.write("vehicle_attitude_setpoint", time_us, yaw_sp_move_rate=yaw_rate, q_d=self.q_sp,
                  thrust_body=thrust_body)  # fmt: skip
        nan3 = np.full(3, np.nan)
        position_sp = sp.position_ned_m if sp else nan3
        log.write(
            "vehicle_local_position_setpoint", time_us, x=position_sp[0], y=position_sp[1],
            z=position_sp[2], yaw=sp.yaw_rad if sp else math.nan, yawspeed=yaw_rate,
            vx=self.velocity_sp[0], vy=self.velocity_sp[1], vz=self.velocity_sp[2],
            acceleration=self.acceleration_sp, thrust=self.thrust_sp_ned,
        )  # fmt: skip
        log.write("vehicle_status", time_us, armed_time=self.armed_time_us,
                  arming_state=2 if self.armed else 1, nav_state=int(self.nav_state),
                  nav_state_user_intention=int(self.user_nav_state), failsafe=self.failsafe,
                  pre_flight_checks_pass=self.preflight_failure() is None)  # fmt: skip
        detector = self.land_detector
        log.write("vehicle_land_detected", time_us, landed=detector.landed,
                  maybe_landed=detector.maybe_landed,
                  ground_contact=detector.ground_contact)  # fmt: skip
        if self.truth is not None and est.origin is not None:
            self._write_truth_errors(log, self.truth, time_us)

    def _write_truth_errors(self, log: ULogWriter, truth: GroundTruth, time_us: int) -> None:
        q_err = quat_multiply(quat_conjugate(truth.q), self.attitude.q)
        attitude_error = 2.0 * math.acos(min(abs(q_err[0]), 1.0))
        z_est, z_true = quat_to_dcm(self.attitude.q)[:, 2], quat_to_dcm(truth.q)[:, 2]
        tilt_error = math.acos(min(max(float(z_est @ z_true), -1.0), 1.0))
        yaw_diff = euler_from_quat(self.attitude.q)[2] - euler_from_quat(truth.q)[2]
        heading_error = (yaw_diff + math.pi) % (2 * math.pi) - math.pi
        true_ned = self._to_local(truth.lat_deg, truth.lon_deg, truth.alt_amsl_m)
        log.write(
            "estimator_groundtruth_error", time_us, attitude_error_rad=attitude_error,
            tilt_error_rad=tilt_error, heading_error_rad=heading_error,
            position_error_m=self.position.position_ned_m - true_ned,
            velocity_error_m_s=self.position.velocity_ned_mps - truth.velocity_ned_mps,
            gyro_bias_rad_s=self.attitude.gyro_bias_radps,
        )  # fmt: skip


def _wmm_declination_rad(lat_deg: float, lon_deg: float) -> float:
    """Declination at the GPS origin from NOAA's World Magnetic Model, as PX4 looks it up in
    its geo tables (ATT_MAG_DECL_A). The epoch is fixed at 2026.0 so runs are reproducible;
    declination drifts about 0.1°/year."""
    from wmm import wmm_calc  # NOAA's model: only needed once, when the origin is set

    model = wmm_calc()
    model.setup_time(dyear=2026.0)
    model.setup_env(lat_deg, lon_deg, 0.0, unit="m", msl=True)
    return math.radians(float(model.get_all()["dec"][0]))
