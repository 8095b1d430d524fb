"""The reference autopilot's optical-flow aiding against closed-form cases.

The estimator is driven as in flight: quad_model's PMW3901 camera frames, summed into the
driver's 20 ms windows (PX4's pmw3901 publishes at 50 Hz), beside a 1 kHz IMU."""

import dataclasses
import math

import numpy as np
import pytest
import pyulog

from quad_model import dynamics as dyn
from quad_model import load_vehicle
from quad_model.environment import Surface
from quad_model.frames import STANDARD_GRAVITY_MPS2, quat_from_euler
from quad_model.model import VehicleTruth
from quad_model.sensors import OpticalFlowModel
from rig.autopilots.reference.estimator import OpticalFlowFusion, PositionEstimator
from rig.autopilots.reference.flight_controller import FlightController
from rig.autopilots.reference.flight_log import open_flight_log
from rig.autopilots.reference.navigator import MissionItem, NavState
from rig.autopilots.reference.params import Parameters
from rig.autopilots.reference.process import flow_reading
from rig.autopilots.reference.sensors import FlowReading, RangeReading, SensorFrame
from rig.mavlink.px4_api import mavlink
from rig.mavlink.sim_messages import hil_optical_flow

FRAME_US = 1000
WINDOW_US = 20_000
BRIGHT = Surface(texture=1.0, illuminance_lux=10_000.0)


def _truth(t_us, down_m, vel_ned, rates, euler_rad):
    state = np.zeros(dyn.X_SIZE)
    state[dyn.X_TIME_US] = t_us
    state[dyn.X_POS + 2] = down_m
    state[dyn.X_VEL : dyn.X_VEL + 3] = vel_ned
    state[dyn.X_RATE : dyn.X_RATE + 3] = rates
    state[dyn.X_QUAT : dyn.X_QUAT + 4] = quat_from_euler(*euler_rad)
    return VehicleTruth(state, np.zeros(dyn.A_SIZE), rotors=4)


def _camera(noise_std_rad=0.0005):
    """The F450's PMW3901 at the body origin (the lever arm is the model's own test)."""
    camera = load_vehicle("f450_high_precision").optical_flow
    assert camera is not None
    return dataclasses.replace(camera, noise_std_rad=noise_std_rad, position_frd_m=(0, 0, 0))


class _Driver:
    """PX4's pmw3901 driver: camera frames summed, published every 20 ms with their mean
    quality, stamped at the publication."""

    def __init__(self, camera, seed=1):
        self.model = OpticalFlowModel(camera, BRIGHT, np.random.default_rng(seed))
        self.motion = np.zeros(2)
        self.squals: list[int] = []
        self.last_us = 0

    def step(self, truth) -> FlowReading | None:
        frame = self.model.sample(truth)
        if frame is not None:
            self.motion += frame.flow_xy_rad
            self.squals.append(frame.squal)
        now = truth.time_us
        if now - self.last_us < WINDOW_US or not self.squals:
            return None
        reading = FlowReading(now, (float(self.motion[0]), float(self.motion[1])),
                              now - self.last_us, round(np.mean(self.squals)))  # fmt: skip
        self.motion, self.squals, self.last_us = np.zeros(2), [], now
        return reading


class _Flight:
    """A position filter and the flow fusion, fed a motion given as functions of time."""

    def __init__(self, params=None):
        params = params or Parameters()
        self.position = PositionEstimator()
        self.position.configure(params)
        self.flow = OpticalFlowFusion()
        self.flow.configure(params)
        self.fused = 0

    def fly(self, driver, seconds, *, down_m=-2.0, vel_ned=(0.0, 0.0, 0.0), rates=None,
            euler=None, start_s=0.0, tamper=None, seen=None):  # fmt: skip
        """``rates(t)`` and ``euler(t)`` (rad) describe the attitude; the vehicle moves at a
        constant ``vel_ned``, so the accelerometer reads gravity only. ``tamper`` replaces a
        window's reading; ``seen`` collects them."""
        first = round(start_s * 1e6 / FRAME_US) + 1
        for k in range(first, first + round(seconds * 1e6 / FRAME_US)):
            t_us = k * FRAME_US
            t_s = t_us * 1e-6
            body_rates = np.zeros(3) if rates is None else np.asarray(rates(t_s))
            angles = (0.0, 0.0, 0.0) if euler is None else euler(t_s)
            truth = _truth(t_us, down_m, vel_ned, body_rates, angles)
            q = quat_from_euler(*angles)
            self.position.predict(np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2]), FRAME_US * 1e-6)
            self.flow.add_gyro(t_us, body_rates, FRAME_US * 1e-6)
            reading = driver.step(truth)
            if reading is not None:
                reading = tamper(reading) if tamper else reading
                if seen is not None:
                    seen.append(reading)
                height = -down_m
                if self.flow.update(reading, self.position, q, height, True, False, t_us):
                    self.fused += 1
        return self


def test_hil_optical_flow_decodes_as_px4s_simulator_reads_it():
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    message = hil_optical_flow(mav, 5_000_000, pixel_flow_rad=(0.012, -0.034),
                               integration_timespan_us=20_000, quality=117)  # fmt: skip
    reading = flow_reading(mav.parse_char(message.pack(mav)), 4_996_000)
    assert reading.time_us == 4_996_000  # PX4 stamps the arrival
    assert reading.pixel_flow_rad == pytest.approx((0.012, -0.034), rel=1e-6)  # float32
    assert (reading.integration_timespan_us, reading.quality) == (20_000, 117)


@pytest.mark.parametrize("yaw_deg", [0.0, 30.0, -120.0])
def test_constant_velocity_at_constant_height_converges_to_the_truth(yaw_deg):
    """1 m/s north and -0.5 m/s east at 2 m, yawed: the flow's first sample starts the
    aiding (velocity reset to the flow's, as EKF2 does: within a window's share of a camera
    frame, 8 of 20 ms); a velocity estimate then knocked to zero is back within 5 cm/s of
    the truth in 2 s and stays there."""
    yaw = math.radians(yaw_deg)
    truth_v = np.array([1.0, -0.5, 0.0])
    flight = _Flight()
    driver = _Driver(_camera())
    flight.fly(driver, 0.05, vel_ned=truth_v, euler=lambda t: (0.0, 0.0, yaw))
    assert flight.flow.active
    assert flight.position.velocity_ned_mps[:2] == pytest.approx(truth_v[:2], rel=0.45)
    flight.position.x[:2, 1] = 0.0
    flight.position.p[:2, 1, 1] = 4.0
    flight.fly(driver, 2.0, vel_ned=truth_v, euler=lambda t: (0.0, 0.0, yaw), start_s=0.05)
    assert flight.position.velocity_ned_mps[:2] == pytest.approx(truth_v[:2], abs=0.05)
    errors = []
    for start in np.arange(2.05, 6.05, 0.5):
        flight.fly(driver, 0.5, vel_ned=truth_v, euler=lambda t: (0.0, 0.0, yaw), start_s=start)
        errors.append(np.abs(flight.position.velocity_ned_mps[:2] - truth_v[:2]).max())
    assert max(errors) < 0.05
    assert flight.fused >= 0.95 * 6.0 / 0.02 - 5  # nearly every window fused
    assert flight.position.rejected == 0


MOUNT_FRD_M = (0.03, 0.0, -0.10)  # the F450's PMW3901, beside the LIDAR-Lite


@pytest.mark.parametrize(
    ("mount", "told", "worst_mps"),
    [((0.0, 0.0, 0.0), False, (0.0, 0.08)), (MOUNT_FRD_M, True, (0.0, 0.08)),
     (MOUNT_FRD_M, False, (0.08, math.inf))],
)  # fmt: skip
def test_pure_rotation_is_compensated_by_the_gyro_to_zero_velocity(mount, told, worst_mps):
    """Hovering still at 2 m and rolling ±10° at 1 Hz: the image swings at up to 1.1 rad/s
    (2.2 m/s if read as motion), the gyro integrated over each window takes it out, and the
    velocity estimate stays within 8 cm/s of zero (the camera's frames straddle the
    windows: measured 6.9 cm/s at most). A camera 10 cm above the centre swings with the
    roll; told its mount (``EKF2_OF_POS_*``) the fusion takes that out too (6.5 cm/s;
    10.6 cm/s untold)."""
    omega = 2.0 * math.pi
    amplitude = math.radians(10.0)

    def euler(t):
        return (amplitude * math.sin(omega * t), 0.0, 0.0)

    def rates(t):
        return (amplitude * omega * math.cos(omega * t), 0.0, 0.0)

    names = ("EKF2_OF_POS_X", "EKF2_OF_POS_Y", "EKF2_OF_POS_Z")
    flight = _Flight(Parameters(dict(zip(names, mount, strict=True)) if told else None))
    driver = _Driver(dataclasses.replace(_camera(), position_frd_m=mount))
    raw: list[FlowReading] = []
    worst = 0.0
    for start in np.arange(0.0, 4.0, 0.1):
        flight.fly(driver, 0.1, rates=rates, euler=euler, start_s=start, seen=raw)
        worst = max(worst, np.abs(flight.position.velocity_ned_mps[:2]).max())
    assert max(abs(r.pixel_flow_rad[0]) / (r.integration_timespan_us * 1e-6) for r in raw) > 1.0
    assert worst_mps[0] < worst < worst_mps[1]
    assert flight.fused >= 195  # of 200 windows


def test_signs_against_the_camera_model():
    """One noiseless window per axis (a camera at 1 kHz fills it exactly): a motion along
    body +x reads +v/r about y, along +y -v/r about x, and the fusion turns each back into
    the body velocity it came from."""
    camera = dataclasses.replace(_camera(0.0), frame_rate_hz=1000.0)
    for vel in ((0.8, 0.0, 0.0), (0.0, 0.8, 0.0)):
        flight = _Flight()
        readings: list[FlowReading] = []
        flight.fly(_Driver(camera), 0.04, down_m=-2.0, vel_ned=vel, seen=readings)
        reading = readings[1]  # the first window's first frame has no motion yet
        rate = np.array(reading.pixel_flow_rad) / 0.02
        assert rate == pytest.approx((-vel[1] / 2.0, vel[0] / 2.0), abs=1e-9)
        assert flight.flow.sample is not None
        assert flight.flow.sample.velocity_body_mps == pytest.approx(vel[:2], abs=1e-9)


def test_quality_zero_in_the_air_is_not_used_and_the_aiding_times_out():
    """After 1 s of good flow, SQUAL 0 (below EKF2_OF_QMIN 1): nothing more is fused, and
    EKF2_NOAID_TOUT (5 s) after the last fusion the flow no longer aids."""
    flight = _Flight()
    driver = _Driver(_camera())
    flight.fly(driver, 1.0)
    last = flight.flow.last_fuse_us
    assert last is not None
    assert last >= 980_000
    fused = flight.fused

    def blind(reading):
        return dataclasses.replace(reading, pixel_flow_rad=(0.0, 0.0), quality=0)

    flight.fly(driver, 5.5, start_s=1.0, tamper=blind)
    assert flight.fused == fused
    assert flight.flow.aiding(last + 5_000_000)
    assert not flight.flow.aiding(last + 5_000_001)


def test_on_the_ground_a_blind_sample_means_standing_still():
    """On the ground EKF2 takes a sample that fails its checks as zero motion, and fuses it."""
    flow = OpticalFlowFusion()
    flow.configure(Parameters(dict(EKF2_OF_QMIN_GND=10)))
    position = PositionEstimator()
    q = quat_from_euler(0.0, 0.0, 0.0)
    for k in range(1, 41):
        flow.add_gyro(k * 1000, np.zeros(3), 1e-3)
        position.predict(np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2]), 1e-3)
    blind = FlowReading(40_000, (0.3, 0.3), 20_000, 0)
    assert not flow.update(blind, position, q, None, False, False, 40_000)  # starts aiding
    assert flow.active
    assert position.position_ned_m[:2] == pytest.approx((0.0, 0.0))
    position.x[:2, 1] = 0.05  # a drift the zero-motion samples take out
    position.p[:2, 1, 1] = 0.01
    for k in range(3, 40):
        t = k * 20_000
        for j in range(t - 19_000, t + 1, 1000):
            flow.add_gyro(j, np.zeros(3), 1e-3)
            position.predict(np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2]), 1e-3)
        assert flow.update(dataclasses.replace(blind, time_us=t), position, q, None, False,
                           False, t)  # fmt: skip
        assert flow.sample is not None
        assert flow.sample.compensated_rad == pytest.approx((0.0, 0.0))
    assert np.abs(position.velocity_ned_mps[:2]).max() < 0.005


def test_an_outlier_is_gated_and_bad_samples_are_refused():
    """Converged at 1 m/s, a window reading 4 m/s fails EKF2_OF_GATE (3σ) and leaves the
    estimate alone; a motion past SENS_FLOW_MAXR or a camera tilted past 45° is not used."""
    flight = _Flight()
    driver = _Driver(_camera())
    flight.fly(driver, 2.0, vel_ned=(1.0, 0.0, 0.0))
    before = flight.position.velocity_ned_mps.copy()
    position, flow = flight.position, flight.flow
    t = 2_020_000
    level = quat_from_euler(0.0, 0.0, 0.0)
    for j in range(2_001_000, t + 1, 1000):
        flow.add_gyro(j, np.zeros(3), 1e-3)
    outlier = FlowReading(t, (0.0, 4.0 / 2.0 * 0.02), 20_000, 120)
    assert not flow.update(outlier, position, level, 2.0, True, False, t)
    assert position.rejected == 2  # both axes, as EKF2 rejects them together
    assert position.velocity_ned_mps == pytest.approx(before, abs=1e-12)
    too_fast = FlowReading(t, (0.0, 8.1 * 0.02), 20_000, 120)
    assert not flow.update(too_fast, position, level, 2.0, True, False, t)
    tilted = quat_from_euler(math.radians(46.0), 0.0, 0.0)
    fine = FlowReading(t, (0.0, 1.0 / 2.0 * 0.02), 20_000, 120)
    assert not flow.update(fine, position, tilted, 2.0 * math.cos(math.radians(46.0)), True,
                           False, t)  # fmt: skip
    assert position.rejected == 2  # refused before the gate
    assert flow.update(fine, position, level, 2.0, True, False, t)


@pytest.mark.parametrize(
    ("quality", "noise_radps"),
    [(0, 0.5), (1, 0.5), (128, 0.5 - 0.35 * 127 / 254), (255, 0.15)],
)
def test_noise_scales_with_quality_between_n_max_and_n_min(quality, noise_radps):
    flow = OpticalFlowFusion()
    flow.configure(Parameters())
    assert flow.noise_radps(quality) == pytest.approx(noise_radps, abs=1e-12)


def test_tilt_lengthens_the_range_along_the_camera_axis():
    """Rolled 30° at 2 m, a sideways 1 m/s reads v/r with r = 2 / cos 30°, and the fusion
    gives back the body velocity from the rangefinder's height."""
    roll = math.radians(30.0)
    q = quat_from_euler(roll, 0.0, 0.0)
    r_range = 2.0 / math.cos(roll)
    flow = OpticalFlowFusion()
    flow.configure(Parameters())
    position = PositionEstimator()
    for j in range(1000, 20_001, 1000):
        flow.add_gyro(j, np.zeros(3), 1e-3)
        position.predict(np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2]), 1e-3)
    reading = FlowReading(20_000, (-1.0 / r_range * 0.02, 0.0), 20_000, 200)
    flow.update(reading, position, q, 2.0, True, False, 20_000)
    assert flow.sample is not None
    assert flow.sample.velocity_body_mps == pytest.approx((0.0, 1.0), abs=1e-9)


def _frame(k, flow_quality, rng):
    """A vehicle at rest, level, facing north at 0.2 m over the ground, without GPS: IMU
    at 250 Hz, the magnetometer and the barometer, the LIDAR-Lite every 5th frame (20 ms,
    close to its 50 ms cycle is enough here), a flow window every 5th frame; a little noise,
    or PX4's checks would call the sensors stale."""
    t_us = k * 4000
    window = k % 5 == 0
    noise = rng.standard_normal(9) * 1e-3
    return t_us, SensorFrame(
        accel_mps2=np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2]) + noise[:3],
        gyro_radps=noise[3:6], mag_gauss=np.array([0.215, 0.0, 0.433]) + noise[6:],
        baro_pressure_pa=101_000.0 + 10.0 * noise[0],
        baro_temperature_degc=15.0,
        range=RangeReading(0.2, 100, 0.05, 25.0) if k % 5 == 0 else None,
        flow=FlowReading(t_us - 4000, (0.0, 0.0), 20_000, flow_quality) if window else None,
    )  # fmt: skip


def _fly_still(fc, first, seconds, flow_quality):
    rng = np.random.default_rng(first)
    for k in range(first, first + round(seconds / 0.004)):
        fc.update(*reversed(_frame(k, flow_quality, rng)))
    return first + round(seconds / 0.004)


def test_without_gps_flow_gives_a_local_position_to_arm_and_take_off_but_no_mission(tmp_path):
    """No HIL_GPS at all: the flow (and the rangefinder's height) make the local position
    valid, so it arms and takes off in the local frame; what needs latitude and longitude
    refuses in one line. Each flow sample used is logged as EKF2 logs it."""
    params = Parameters({"ATT_MAG_DECL_A": 0})
    log = open_flight_log(tmp_path / "autopilot.ulg", params.as_dict())
    fc = FlightController(params, log)
    k = _fly_still(fc, 1, 3.0, 150)
    assert fc.flow.active
    assert fc.position_valid()
    assert fc.position.origin is None
    assert fc.preflight_failure() is None
    assert fc.arm().result == mavlink.MAV_RESULT_ACCEPTED
    assert fc.home is not None
    refused = fc.takeoff(500.0)
    assert refused.reason == "Takeoff denied: an altitude AMSL needs a global position"
    assert fc.takeoff(math.nan).result == mavlink.MAV_RESULT_ACCEPTED
    assert fc.navigator.takeoff_target_ned[2] == pytest.approx(
        fc.navigator.home_ned[2] - Parameters()["MIS_TAKEOFF_ALT"]
    )
    fc.set_mission([MissionItem(0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                mavlink.MAV_CMD_NAV_WAYPOINT, 0.0, 0.0, 0.0, math.nan,
                                473_977_000, 85_456_000, 5.0)])  # fmt: skip
    refused = fc.set_mode(NavState.AUTO_MISSION)
    assert refused.reason == "Switching to mission denied: no global position (GPS)"
    _fly_still(fc, k, 0.1, 150)
    assert fc.nav_state == NavState.AUTO_TAKEOFF
    log.close()
    flow = pyulog.ULog(str(tmp_path / "autopilot.ulg")).get_dataset("estimator_optical_flow_vel")
    assert len(flow.data["timestamp"]) == round(3.1 / 0.02)  # every window
    assert np.abs(flow.data["vel_body[0]"]).max() < 0.01  # at rest


def test_flow_lost_in_the_air_for_noaid_tout_triggers_the_descend_failsafe():
    """Hovering on flow (held in the air here: the land detector told so), SQUAL 0 from
    t = 3 s: EKF2_NOAID_TOUT (5 s) after the last fusion the local position is invalid and,
    as PX4's failsafe falls back when neither Hold nor Land can run, it descends, saying
    why."""
    fc = FlightController(Parameters({"ATT_MAG_DECL_A": 0, "COM_DISARM_PRFLT": -1}))
    k = _fly_still(fc, 1, 3.0, 150)
    assert fc.arm().result == mavlink.MAV_RESULT_ACCEPTED
    fc.land_detector.landed = False
    k = _fly_still(fc, k, 4.9, 0)
    assert fc.nav_state == NavState.AUTO_LOITER
    assert fc.position_valid()
    _fly_still(fc, k, 0.3, 0)
    assert fc.nav_state == NavState.DESCEND
    texts = [text for _, text in fc.status_messages]
    assert "Failsafe: no position (optical flow lost), Descend" in texts
