"""Optical-flow camera physics: closed-form image motion (translation over the range, body
rates, tilt, the mount's lever arm), saturation, what the camera cannot see, the quality's
fall with texture, light and blur, the noise level and determinism."""

import dataclasses
import math

import numpy as np
import pytest

from quad_model import SensorSuite
from quad_model import dynamics as dyn
from quad_model.environment import Environment, Surface
from quad_model.frames import quat_from_euler
from quad_model.model import VehicleTruth
from quad_model.sensors import OpticalFlowModel, SensorConfigError

BRIGHT = Surface(texture=1.0, illuminance_lux=10_000.0)


def truth(t_us, down_m=-2.0, vel_ned=(0.0, 0.0, 0.0), rates=(0.0, 0.0, 0.0), euler_deg=(0, 0, 0)):
    state = np.zeros(dyn.X_SIZE)
    state[dyn.X_TIME_US] = t_us
    state[dyn.X_POS + 2] = down_m
    state[dyn.X_VEL : dyn.X_VEL + 3] = vel_ned
    state[dyn.X_RATE : dyn.X_RATE + 3] = rates
    state[dyn.X_QUAT : dyn.X_QUAT + 4] = quat_from_euler(*(math.radians(a) for a in euler_deg))
    return VehicleTruth(state, np.zeros(dyn.A_SIZE), rotors=4)


@pytest.fixture
def camera(f450, variant):
    """The F450's PMW3901 at the body origin, without noise: every motion is the closed form."""
    return variant(f450, optical_flow={"noise_std_rad": 0.0, "position_frd_m": (0, 0, 0)}
                   ).optical_flow  # fmt: skip


def fly(model, seconds, frame_us=1000, **state):
    """Call the model every rig frame; the camera frames it returned."""
    frames = []
    for k in range(round(seconds * 1e6 / frame_us) + 1):
        sample = model.sample(truth(k * frame_us, **state))
        if sample is not None:
            frames.append(sample)
    return frames


def total_motion(frames):
    return np.sum([f.flow_xy_rad for f in frames], axis=0)


def test_translation_reads_velocity_over_range_in_px4s_sign_convention(camera):
    """Level at 2 m, 1 m/s north and 0.5 m/s east (yaw 0, so body x, y): over 1 s the image
    turns v_x/r = +0.5 rad about y and -v_y/r = -0.25 rad about x (PX4's sensor_optical_flow:
    a motion along +y reads negative about x, along +x positive about y)."""
    model = OpticalFlowModel(camera, BRIGHT, np.random.default_rng(1))
    frames = fly(model, 1.0, down_m=-2.0, vel_ned=(1.0, 0.5, 0.0))
    assert len(frames) == 127  # a frame at t = 0, then 126 frames a second
    assert total_motion(frames) == pytest.approx((-0.25, 0.5), abs=1e-12)
    assert all(f.squal == 230 for f in frames)


def test_body_rates_turn_the_whole_image(camera):
    """Hovering still and rolling at 0.3 rad/s, pitching at -0.2: the image turns with the
    body (what PX4 compensates with the gyro)."""
    model = OpticalFlowModel(camera, BRIGHT, np.random.default_rng(1))
    frames = fly(model, 1.0, rates=(0.3, -0.2, 0.9))
    assert total_motion(frames) == pytest.approx((0.3, -0.2), abs=1e-12)


def test_yaw_turns_the_velocity_into_body_axes_and_tilt_lengthens_the_range(camera):
    """Yawed 90° and moving north: that is body -y, so it reads +v/r about x. Rolled 30°,
    the range along the camera axis is h / cos 30°."""
    model = OpticalFlowModel(camera, BRIGHT, np.random.default_rng(1))
    frames = fly(model, 1.0, down_m=-3.0, vel_ned=(1.2, 0.0, 0.0), euler_deg=(0, 0, 90))
    assert total_motion(frames) == pytest.approx((1.2 / 3.0, 0.0), abs=1e-12)
    model = OpticalFlowModel(camera, BRIGHT, np.random.default_rng(1))
    frames = fly(model, 1.0, down_m=-3.0, vel_ned=(1.2, 0.0, 0.0), euler_deg=(30, 0, 0))
    r = 3.0 / math.cos(math.radians(30))
    # Rolled about x, north is still body x: only the range changed.
    assert total_motion(frames) == pytest.approx((0.0, 1.2 / r), abs=1e-12)


def test_the_mount_lever_arm_moves_with_the_body_rate(f450, variant):
    """A camera 0.2 m ahead of the origin, yawing at 1 rad/s: it moves at 0.2 m/s along body
    +y, which reads -0.2/r about x (r = 2 m: the mount is level with the origin)."""
    params = variant(f450, optical_flow={"noise_std_rad": 0.0, "position_frd_m": (0.2, 0, 0)}
                     ).optical_flow  # fmt: skip
    model = OpticalFlowModel(params, BRIGHT, np.random.default_rng(1))
    frames = fly(model, 1.0, down_m=-2.0, rates=(0.0, 0.0, 1.0))
    assert total_motion(frames) == pytest.approx((-0.1, 0.0), abs=1e-12)


def test_faster_than_the_chip_tracks_saturates_at_its_maximum_rate(camera):
    """12 m/s at 1 m is 12 rad/s of image motion: each frame reads the 7.4 rad/s limit."""
    model = OpticalFlowModel(camera, BRIGHT, np.random.default_rng(1))
    frames = fly(model, 0.2, down_m=-1.0, vel_ned=(12.0, 0.0, 0.0))[1:]
    frame_s = np.diff([f.time_us for f in frames]) / 1e6
    rate = np.array([f.flow_xy_rad[1] for f in frames[1:]]) / frame_s
    assert rate == pytest.approx(7.4, rel=1e-9)


def test_out_of_focus_or_tilted_away_the_camera_sees_nothing(camera):
    model = OpticalFlowModel(camera, BRIGHT, np.random.default_rng(1))
    near = fly(model, 0.1, down_m=-0.05, vel_ned=(1.0, 0.0, 0.0))  # 5 cm < 80 mm
    assert {f.squal for f in near} == {0}
    assert {f.flow_xy_rad for f in near} == {(0.0, 0.0)}
    model = OpticalFlowModel(camera, BRIGHT, np.random.default_rng(1))
    tilted = fly(model, 0.1, down_m=-3.0, euler_deg=(50, 0, 0))
    assert {f.squal for f in tilted} == {0}


def test_quality_falls_with_texture_light_and_blur(camera):
    """SQUAL = squal_max · texture · min(1, lux / full_exposure_lux) / (1 + blur²), the
    blur being the pixels the image smears over the exposure (one frame in dim light)."""

    def squal(surface, **state):
        frames = fly(OpticalFlowModel(camera, surface, np.random.default_rng(1)), 0.1, **state)
        return frames[-1].squal

    assert squal(Surface(texture=0.5, illuminance_lux=10_000)) == 115
    assert squal(Surface(texture=1.0, illuminance_lux=30)) == 115  # half the full-exposure light
    assert squal(Surface(texture=0.0, illuminance_lux=10_000)) == 0
    # In dim light the exposure is a whole frame: 2 rad/s smears 2/126/pixel_rad pixels.
    blur = 2.0 / 126.0 / camera.pixel_rad
    dim = Surface(texture=1.0, illuminance_lux=60)
    assert squal(dim, rates=(2.0, 0.0, 0.0)) == round(230 / (1 + blur**2))
    # In daylight the exposure is 60/10,000 of a frame: the same rate barely blurs.
    assert squal(BRIGHT, rates=(2.0, 0.0, 0.0)) == 230


def test_noise_level_and_determinism(f450):
    """The frame noise has the file's σ on a fully textured surface in good light, σ/√(texture)
    on a poorer one; the same seed gives the same frames."""
    params = f450.optical_flow
    frames = fly(OpticalFlowModel(params, BRIGHT, np.random.default_rng(7)), 10.0, down_m=-2.0)
    motion = np.array([f.flow_xy_rad for f in frames])
    # The F450's mount is 0.10 m up the body: hovering still, the truth is zero motion.
    assert motion.std(axis=0) == pytest.approx(params.noise_std_rad, rel=0.05)
    poor = Surface(texture=0.25, illuminance_lux=10_000)
    frames = fly(OpticalFlowModel(params, poor, np.random.default_rng(7)), 10.0, down_m=-2.0)
    noisy = np.array([f.flow_xy_rad for f in frames])
    assert noisy.std(axis=0) == pytest.approx(2 * params.noise_std_rad, rel=0.05)
    again = fly(OpticalFlowModel(params, BRIGHT, np.random.default_rng(7)), 10.0, down_m=-2.0)
    assert [f.flow_xy_rad for f in again] == [tuple(m) for m in motion]


def test_the_suite_flies_the_camera_only_when_asked_and_only_on_a_vehicle_with_one(f450, x500):
    """Asking for the camera leaves every other sensor's numbers as they were."""
    env = Environment()

    def run(vehicle, **kwargs):
        suite = SensorSuite(vehicle, env, np.random.default_rng(3), rangefinder_rate_hz=20.0,
                            **kwargs)  # fmt: skip
        return [suite.sample(truth(k * 1000)) for k in range(50)]

    plain, with_flow = run(f450), run(f450, optical_flow=True)
    assert all(r.flow is None for r in plain)
    assert sum(r.flow is not None for r in with_flow) == 7  # at 0, 8, 16, 24, 32, 40 and 48 ms
    for a, b in zip(plain, with_flow, strict=True):
        assert np.array_equal(a.imu.gyro_radps, b.imu.gyro_radps)
        assert a.range == b.range
    without = dataclasses.replace(x500, optical_flow=None)
    with pytest.raises(SensorConfigError, match=r"has no \[optical_flow\] table"):
        SensorSuite(without, env, np.random.default_rng(3), optical_flow=True)
