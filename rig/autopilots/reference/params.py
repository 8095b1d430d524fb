"""PX4's parameters for the reference autopilot: names, defaults, units and ranges.

A PX4 user tunes this autopilot with the knobs they know. Every default is PX4's (the
``*_params.yaml`` file named beside each group in PX4-Autopilot ``main``) unless the line
says why it differs. Values travel over MAVLink as float32 (``REAL32``) or int32
(``INT32``, encoded bytewise as PX4 does).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import numpy as np

from quad_model.vehicle import MAX_ROTORS, MIN_ROTORS


class ParameterError(ValueError):
    """An unknown parameter name, or a value outside the parameter's range."""


@dataclass(frozen=True)
class ParamSpec:
    """One parameter as PX4 documents it."""

    name: str
    default: float | int
    minimum: float
    maximum: float
    unit: str
    description: str

    @property
    def is_int(self) -> bool:
        return isinstance(self.default, int)


def _p(
    name: str, default: float | int, minimum: float, maximum: float, unit: str, text: str
) -> ParamSpec:
    return ParamSpec(name, default, minimum, maximum, unit, text)


_INF = math.inf
# Rotor geometry of PX4 SITL airframe 10016 (quad X, front = +x, right = +y), as its
# airframe file sets it (PX4-Autopilot ``ROMFS/px4fmu_common/init.d-posix/airframes/
# 10016_none_iris``, the same in v1.14 and v1.17); CA_ROTORi_KM > 0 for CCW rotors (PX4
# control_allocator module docs: "positive for CCW rotation"). Rotors past the fourth have
# PX4's defaults (at the centre, KM 0.05) until an airframe places them.
_ROTORS = ((0.1515, 0.245, 0.05), (-0.1515, -0.1875, 0.05), (0.1515, -0.245, -0.05),
           (-0.1515, 0.1875, -0.05), *((0.0, 0.0, 0.05),) * (MAX_ROTORS - 4))  # fmt: skip

PARAMETERS: tuple[ParamSpec, ...] = (
    # src/modules/mc_rate_control/mc_rate_control_params.yaml
    _p("MC_ROLLRATE_P", 0.15, 0.01, 0.5, "", "Roll rate P gain"),
    _p("MC_ROLLRATE_I", 0.2, 0.0, _INF, "", "Roll rate I gain"),
    _p("MC_ROLLRATE_D", 0.003, 0.0, 0.01, "", "Roll rate D gain"),
    _p("MC_ROLLRATE_FF", 0.0, 0.0, _INF, "", "Roll rate feedforward"),
    _p("MC_ROLLRATE_K", 1.0, 0.01, 5.0, "", "Roll rate controller gain"),
    _p("MC_RR_INT_LIM", 0.3, 0.0, _INF, "", "Roll rate integrator limit"),
    _p("MC_PITCHRATE_P", 0.15, 0.01, 0.6, "", "Pitch rate P gain"),
    _p("MC_PITCHRATE_I", 0.2, 0.0, _INF, "", "Pitch rate I gain"),
    _p("MC_PITCHRATE_D", 0.003, 0.0, _INF, "", "Pitch rate D gain"),
    _p("MC_PITCHRATE_FF", 0.0, 0.0, _INF, "", "Pitch rate feedforward"),
    _p("MC_PITCHRATE_K", 1.0, 0.01, 5.0, "", "Pitch rate controller gain"),
    _p("MC_PR_INT_LIM", 0.3, 0.0, _INF, "", "Pitch rate integrator limit"),
    _p("MC_YAWRATE_P", 0.2, 0.0, 0.6, "", "Yaw rate P gain"),
    _p("MC_YAWRATE_I", 0.1, 0.0, _INF, "", "Yaw rate I gain"),
    _p("MC_YAWRATE_D", 0.0, 0.0, _INF, "", "Yaw rate D gain"),
    _p("MC_YAWRATE_FF", 0.0, 0.0, _INF, "", "Yaw rate feedforward"),
    _p("MC_YAWRATE_K", 1.0, 0.01, 5.0, "", "Yaw rate controller gain"),
    _p("MC_YR_INT_LIM", 0.3, 0.0, _INF, "", "Yaw rate integrator limit"),
    # PX4 v1.15 on (in the X500 and 8S quad logs' v1.16/v1.17; not in the v1.14 SITL)
    _p("MC_YAW_TQ_CUTOFF", 2.0, 0.0, 10.0, "Hz", "Yaw torque setpoint low-pass cutoff (0: off)"),
    # src/modules/sensors/vehicle_angular_velocity/imu_gyro_parameters.yaml
    _p("IMU_GYRO_CUTOFF", 40.0, 0.0, 1000.0, "Hz", "Low pass filter cutoff for the gyro"),
    _p("IMU_DGYRO_CUTOFF", 30.0, 0.0, 1000.0, "Hz", "Cutoff for the angular acceleration (D-term)"),
    # src/modules/sensors/vehicle_imu/imu_parameters.c: sensor_combined's averaging interval
    _p("IMU_INTEG_RATE", 200, 100, 1000, "Hz", "IMU integration rate (sensor_combined)"),
    # src/modules/mc_att_control/mc_att_control_params.yaml
    _p("MC_ROLL_P", 4.0, 0.0, 12.0, "", "Roll P gain (rad/s per rad)"),
    _p("MC_PITCH_P", 4.0, 0.0, 12.0, "", "Pitch P gain (rad/s per rad)"),
    _p("MC_YAW_P", 2.8, 0.0, 5.0, "", "Yaw P gain (rad/s per rad)"),
    _p("MC_YAW_WEIGHT", 0.4, 0.0, 1.0, "", "Yaw weight against roll and pitch"),
    _p("MC_ROLLRATE_MAX", 220.0, 0.0, 1800.0, "deg/s", "Max roll rate"),
    _p("MC_PITCHRATE_MAX", 220.0, 0.0, 1800.0, "deg/s", "Max pitch rate"),
    _p("MC_YAWRATE_MAX", 200.0, 0.0, 1800.0, "deg/s", "Max yaw rate"),
    # src/modules/mc_pos_control/multicopter_position_control_gain_params.yaml
    _p("MPC_XY_P", 0.95, 0.0, 2.0, "", "Horizontal position P gain (m/s per m)"),
    _p("MPC_Z_P", 1.0, 0.1, 1.5, "", "Vertical position P gain (m/s per m)"),
    _p("MPC_XY_VEL_P_ACC", 1.8, 1.2, 5.0, "", "Horizontal velocity P gain (m/s² per m/s)"),
    _p("MPC_XY_VEL_I_ACC", 0.4, 0.0, 60.0, "", "Horizontal velocity I gain"),
    _p("MPC_XY_VEL_D_ACC", 0.2, 0.1, 2.0, "", "Horizontal velocity D gain"),
    _p("MPC_Z_VEL_P_ACC", 4.0, 2.0, 15.0, "", "Vertical velocity P gain (m/s² per m/s)"),
    _p("MPC_Z_VEL_I_ACC", 2.0, 0.2, 3.0, "", "Vertical velocity I gain"),
    _p("MPC_Z_VEL_D_ACC", 0.0, 0.0, 2.0, "", "Vertical velocity D gain"),
    # src/modules/mc_pos_control/multicopter_position_control_params.yaml
    _p("MPC_THR_HOVER", 0.5, 0.1, 0.8, "norm", "Vertical thrust required to hover"),
    _p("MPC_THR_XY_MARG", 0.3, 0.0, 0.5, "norm", "Horizontal thrust margin"),
    _p("MPC_VELD_LP", 5.0, 0.0, 50.0, "Hz", "Velocity derivative low pass cutoff"),
    # src/modules/mc_pos_control/multicopter_position_control_limits_params.yaml
    _p("MPC_XY_VEL_MAX", 12.0, 0.0, 20.0, "m/s", "Maximum horizontal velocity"),
    _p("MPC_Z_VEL_MAX_UP", 3.0, 0.5, 8.0, "m/s", "Maximum ascent velocity"),
    _p("MPC_Z_VEL_MAX_DN", 1.5, 0.5, 4.0, "m/s", "Maximum descent velocity"),
    _p("MPC_TILTMAX_AIR", 45.0, 20.0, 89.0, "deg", "Maximum tilt angle in air"),
    _p("MPC_THR_MIN", 0.12, 0.05, 0.5, "norm", "Minimum collective thrust"),
    _p("MPC_THR_MAX", 1.0, 0.0, 1.0, "norm", "Maximum collective thrust"),
    # src/modules/mc_pos_control/multicopter_autonomous_params.yaml
    _p("MPC_XY_CRUISE", 5.0, 3.0, 20.0, "m/s", "Horizontal velocity in autonomous modes"),
    _p("MPC_Z_V_AUTO_UP", 3.0, 0.5, 8.0, "m/s", "Ascent velocity in autonomous modes"),
    _p("MPC_Z_V_AUTO_DN", 1.5, 0.5, 4.0, "m/s", "Descent velocity in autonomous modes"),
    _p("MPC_ACC_HOR", 3.0, 2.0, 15.0, "m/s^2", "Horizontal acceleration in autonomous modes"),
    _p("MPC_JERK_AUTO", 4.0, 1.0, 80.0, "m/s^3", "Jerk limit in autonomous modes"),
    _p("MPC_XY_ERR_MAX", 2.0, 0.1, 10.0, "m", "Maximum horizontal error allowed by the trajectory"),
    _p("MPC_YAWRAUTO_MAX", 60.0, 5.0, 360.0, "deg/s", "Max yaw rate in autonomous modes"),
    # src/modules/mc_pos_control/multicopter_position_mode_params.yaml
    _p("MPC_ACC_UP_MAX", 4.0, 2.0, 15.0, "m/s^2", "Maximum upwards acceleration"),
    _p("MPC_ACC_DOWN_MAX", 3.0, 2.0, 15.0, "m/s^2", "Maximum downwards acceleration"),
    # src/modules/mc_pos_control/multicopter_takeoff_land_params.yaml
    # src/modules/mc_pos_control/mc_pos_control_params.c: the manual modes (Position, Altitude)
    _p("MPC_HOLD_DZ", 0.1, 0.0, 1.0, "", "Deadzone of the sticks where position hold is enabled"),
    _p("MPC_XY_MAN_EXPO", 0.6, 0.0, 1.0, "", "Manual position control stick exponential curve"),
    _p("MPC_Z_MAN_EXPO", 0.6, 0.0, 1.0, "", "Manual control stick vertical exponential curve"),
    _p("MPC_YAW_EXPO", 0.6, 0.0, 1.0, "", "Manual control stick yaw rotation exponential curve"),
    _p("MPC_VEL_MANUAL", 10.0, 3.0, 20.0, "m/s", "Maximum horizontal speed in Position mode"),
    _p("MPC_HOLD_MAX_XY", 0.8, 0.0, 3.0, "m/s", "Below this speed the position is held"),
    _p("MPC_HOLD_MAX_Z", 0.6, 0.0, 3.0, "m/s", "Below this climb rate the height is held"),
    _p("MPC_MAN_Y_MAX", 150.0, 0.0, 400.0, "deg/s", "Max manual yaw rate"),
    _p("MPC_MAN_Y_TAU", 0.08, 0.0, 5.0, "s", "Manual yaw rate input filter time constant"),
    _p("MPC_MAN_TILT_MAX", 35.0, 0.0, 90.0, "deg", "Maximal tilt angle in Altitude mode"),
    # src/modules/mc_att_control/mc_att_control_params.c
    _p("MC_MAN_TILT_TAU", 0.0, 0.0, 2.0, "s", "Manual tilt input filter time constant"),
    _p("MPC_TKO_SPEED", 1.5, 1.0, 5.0, "m/s", "Takeoff climb rate"),
    _p("MPC_TKO_RAMP_T", 3.0, 0.0, 5.0, "s", "Smooth takeoff ramp time constant"),
    _p("MPC_LAND_SPEED", 0.7, 0.6, _INF, "m/s", "Landing descend rate"),
    _p("MPC_LAND_ALT1", 10.0, 0.0, 122.0, "m", "Below: descent slows towards MPC_LAND_SPEED"),
    _p("MPC_LAND_ALT2", 5.0, 0.0, 122.0, "m", "Below: descent at MPC_LAND_SPEED"),
    _p("MPC_LAND_ALT3", 1.0, 0.0, 122.0, "m", "Below (rangefinder): descent at MPC_LAND_CRWL"),
    _p("MPC_LAND_CRWL", 0.3, 0.1, _INF, "m/s", "Landing crawl speed (rangefinder only)"),
    # src/modules/attitude_estimator_q/attitude_estimator_q_params.yaml
    _p("ATT_W_ACC", 0.2, 0.0, 1.0, "", "Complementary filter accelerometer weight"),
    _p("ATT_W_MAG", 0.1, 0.0, 1.0, "", "Complementary filter magnetometer weight"),
    _p("ATT_W_GYRO_BIAS", 0.1, 0.0, 1.0, "", "Complementary filter gyro bias weight"),
    _p("ATT_MAG_DECL", 0.0, -180.0, 180.0, "deg", "Magnetic declination (when not automatic)"),
    _p("ATT_MAG_DECL_A", 1, 0, 1, "", "Declination from the WMM at the GPS origin"),
    # PX4's default is 0 because EKF2, not this filter, flies PX4 vehicles; here the filter is
    # the only attitude source, and without compensation a sustained horizontal acceleration
    # tilts the estimate, so compensation is on by default.
    _p("ATT_ACC_COMP", 1, 0, 1, "", "Acceleration compensation from the velocity estimate"),
    _p("ATT_BIAS_MAX", 0.05, 0.0, 2.0, "rad/s", "Gyro bias limit"),
    # src/modules/ekf2/params_*.yaml: the noise figures of the position/velocity filter
    _p("EKF2_ACC_NOISE", 0.35, 0.01, 1.0, "m/s^2", "Accelerometer noise for prediction"),
    _p("EKF2_ACC_B_NOISE", 0.003, 0.0, 0.01, "m/s^3", "Accelerometer bias random walk"),
    _p("EKF2_GYR_NOISE", 0.015, 0.0001, 0.1, "rad/s", "Rate gyro noise for prediction"),
    _p("EKF2_PREDICT_US", 10000, 1000, 20000, "us", "EKF prediction period"),
    _p("EKF2_GPS_P_NOISE", 0.5, 0.01, 10.0, "m", "GPS horizontal position noise"),
    _p("EKF2_GPS_V_NOISE", 0.3, 0.01, 5.0, "m/s", "GPS velocity noise"),
    _p("EKF2_GPS_DELAY", 110.0, 0.0, 300.0, "ms", "GPS measurement delay relative to IMU"),
    _p("EKF2_HGT_REF", 1, 0, 1, "", "Height reference: 0 barometer, 1 GPS"),
    _p("EKF2_BARO_NOISE", 3.5, 0.01, 15.0, "m", "Barometric altitude noise"),
    _p("EKF2_REQ_EPH", 3.0, 2.0, 100.0, "m", "Required GPS horizontal accuracy to start"),
    _p("EKF2_REQ_NSATS", 6, 4, 12, "", "Required satellite count to start"),
    _p("EKF2_RNG_CTRL", 1, 0, 2, "", "Rangefinder height aid: 0 off, 1 low and slow, 2 always"),
    _p("EKF2_RNG_A_HMAX", 5.0, 1.0, 10.0, "m", "Range aid: below this height above ground"),
    _p("EKF2_RNG_A_VMAX", 1.0, 0.1, 2.0, "m/s", "Range aid: below this horizontal speed"),
    _p("EKF2_RNG_NOISE", 0.1, 0.01, 1.0, "m", "Rangefinder height noise"),
    _p("EKF2_MIN_RNG", 0.1, 0.01, _INF, "m", "Expected rangefinder reading on the ground"),
    _p("EKF2_GPS_CTRL", 7, 0, 15, "", "GNSS aiding: bit 0 lat/lon, 1 altitude, 2 velocity"),
    _p(
        "EKF2_NOAID_TOUT",
        5000000,
        500000,
        10000000,
        "us",
        "Time without horizontal aiding before the position is invalid",
    ),
    # src/modules/ekf2/params_optical_flow.yaml (main: aiding on by default; v1.14-v1.15: off)
    _p("EKF2_OF_CTRL", 1, 0, 1, "", "Optical flow aiding"),
    _p("EKF2_OF_DELAY", 20.0, 0.0, 300.0, "ms", "Optical flow measurement delay"),
    _p("EKF2_OF_QMIN", 1, 0, 255, "", "In-air optical flow minimum quality"),
    _p("EKF2_OF_QMIN_GND", 0, 0, 255, "", "On-ground optical flow minimum quality"),
    _p("EKF2_OF_N_MIN", 0.15, 0.05, _INF, "rad/s", "Optical flow noise at the best quality"),
    _p("EKF2_OF_N_MAX", 0.5, 0.05, _INF, "rad/s", "Optical flow noise at the worst quality"),
    _p("EKF2_OF_GATE", 3.0, 1.0, _INF, "SD", "Gate size for optical flow fusion"),
    _p("EKF2_OF_POS_X", 0.0, -_INF, _INF, "m", "Optical flow focal point, body x (forward)"),
    _p("EKF2_OF_POS_Y", 0.0, -_INF, _INF, "m", "Optical flow focal point, body y (right)"),
    _p("EKF2_OF_POS_Z", 0.0, -_INF, _INF, "m", "Optical flow focal point, body z (down)"),
    # src/modules/sensors/sensor_params_flow.c: HIL_OPTICAL_FLOW reports no limit of its own
    _p("SENS_FLOW_MAXR", 8.0, 1.0, _INF, "rad/s", "Maximum flow rate the sensor measures"),
    # src/modules/commander/commander_params.yaml
    _p("COM_SPOOLUP_TIME", 1.0, 0.0, 5.0, "s", "Motor spool-up time before takeoff"),
    _p("COM_DISARM_LAND", 2.0, -1.0, 20.0, "s", "Auto-disarm after landing (-1: never)"),
    _p("COM_DISARM_PRFLT", 10.0, -1.0, 20.0, "s", "Auto-disarm if no takeoff (-1: never)"),
    _p("COM_RC_LOSS_T", 0.5, 0.0, 35.0, "s", "Manual control loss timeout"),
    _p("COM_OF_LOSS_T", 1.0, 0.0, 60.0, "s", "Offboard setpoint loss timeout"),
    _p("COM_POS_FS_DELAY", 1.0, 1.0, 100.0, "s", "GPS loss failsafe delay"),
    _p("COM_IMU_LOSS_T", 0.1, 0.01, 10.0, "s", "IMU loss timeout (motors off)"),
    _p("SYS_HAS_MAG", 1, 0, 1, "", "A magnetometer is required"),
    _p("SYS_HAS_BARO", 1, 0, 1, "", "A barometer is required"),
    # src/modules/navigator/{navigator,mission}_params.yaml
    _p("NAV_ACC_RAD", 10.0, 0.05, 200.0, "m", "Default mission acceptance radius"),
    _p("NAV_MC_ALT_RAD", 0.8, 0.05, 200.0, "m", "Multicopter altitude acceptance radius"),
    _p("MIS_TAKEOFF_ALT", 2.5, 0.0, _INF, "m", "Default takeoff altitude above home"),
    # src/modules/land_detector/land_detector_params_mc.yaml
    _p("LNDMC_Z_VEL_MAX", 0.25, 0.1, 10.0, "m/s", "Vertical speed below which landed is possible"),
    _p("LNDMC_XY_VEL_MAX", 1.5, 0.0, 10.0, "m/s", "Horizontal speed limit for landed"),
    _p("LNDMC_ROT_MAX", 20.0, 0.0, 360.0, "deg/s", "Roll/pitch rate limit for landed"),
    # src/modules/land_detector/land_detector_params.yaml: all three stages together
    _p("LNDMC_TRIG_TIME", 1.0, 0.1, 10.0, "s", "Land detector trigger time"),
    # src/modules/mavlink/mavlink_params.yaml
    _p("MAV_SYS_ID", 1, 1, 250, "", "MAVLink system id"),
    # src/modules/control_allocator/module.yaml: rotor i at (PX, PY, PZ), thrust along -z;
    # PX4 takes up to 12 rotors, the rig's vehicles have MIN_ROTORS to MAX_ROTORS
    _p("CA_ROTOR_COUNT", 4, MIN_ROTORS, MAX_ROTORS, "", "Number of rotors"),
    *(
        spec
        for i, (x, y, km) in enumerate(_ROTORS)
        for spec in (
            _p(f"CA_ROTOR{i}_PX", x, -100.0, 100.0, "m", f"Rotor {i} position x (forward)"),
            _p(f"CA_ROTOR{i}_PY", y, -100.0, 100.0, "m", f"Rotor {i} position y (right)"),
            _p(f"CA_ROTOR{i}_PZ", 0.0, -100.0, 100.0, "m", f"Rotor {i} position z (down)"),
            _p(f"CA_ROTOR{i}_CT", 6.5, 0.0, 100.0, "", f"Rotor {i} thrust coefficient"),
            _p(f"CA_ROTOR{i}_KM", km, -1.0, 1.0, "", f"Rotor {i} moment ratio (+ for CCW)"),
        )
    ),
)

_SPECS = {spec.name: spec for spec in PARAMETERS}


class Parameters:
    """The live parameter set: PX4 defaults, then overrides, each checked against its range.

    ``version`` increases on every change so controllers re-read their gains only then,
    keeping the per-frame cost free of dictionary look-ups.
    """

    def __init__(self, overrides: Mapping[str, float] | None = None) -> None:
        self._values: dict[str, float | int] = {s.name: s.default for s in PARAMETERS}
        self.version = 0
        for name, value in (overrides or {}).items():
            self.set(name, value)

    def __getitem__(self, name: str) -> float | int:
        try:
            return self._values[name]
        except KeyError:
            raise ParameterError(f"unknown parameter {name!r}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    @staticmethod
    def spec(name: str) -> ParamSpec:
        try:
            return _SPECS[name]
        except KeyError:
            raise ParameterError(f"unknown parameter {name!r}") from None

    def index(self, name: str) -> int:
        """Position of ``name`` in the MAVLink parameter list (``param_index``)."""
        return list(self._values).index(self.spec(name).name)

    def name_at(self, index: int) -> str:
        names = list(self._values)
        if not 0 <= index < len(names):
            raise ParameterError(f"parameter index {index} out of range 0..{len(names) - 1}")
        return names[index]

    def set(self, name: str, value: float) -> float | int:
        """Set ``name`` after checking its range; returns the value stored."""
        spec = self.spec(name)
        if not math.isfinite(value):
            raise ParameterError(f"parameter {name}: value {value} is not finite")
        if spec.is_int:
            if value != int(value):
                raise ParameterError(f"parameter {name}: {value} is not an integer")
            value = int(value)
        else:
            value = float(value)
        # PX4's parameters are float32, and so are a log's: 0.01 there is 0.0099999998, inside
        # a 0.01 minimum, as PX4 compares it.
        low, high, single = (np.float32(v) for v in (spec.minimum, spec.maximum, value))
        if not low <= single <= high:
            raise ParameterError(
                f"parameter {name}: {value} outside {spec.minimum}..{spec.maximum} {spec.unit}"
            )
        if self._values[name] != value:
            self._values[name] = value
            self.version += 1
        return value

    def as_dict(self) -> dict[str, float | int]:
        return dict(self._values)


def is_parameter(name: str) -> bool:
    """Whether the reference autopilot has a parameter ``name``."""
    return name in _SPECS


def parse_assignment(text: str) -> tuple[str, float]:
    """``"MPC_XY_P=1.2"`` → ``("MPC_XY_P", 1.2)`` (the ``--param`` command-line form)."""
    name, sep, raw = text.partition("=")
    if not sep or not name:
        raise ParameterError(f"--param {text!r}: expected NAME=VALUE")
    Parameters.spec(name)
    try:
        value = float(raw)
    except ValueError:
        raise ParameterError(f"--param {text!r}: value {raw!r} is not a number") from None
    return name, value
