"""The reference autopilot's rangefinder: DISTANCE_SENSOR decoding, the height above the
ground and its validity, the range aid, the landing crawl and the land detector's
close-to-ground check, each against a hand-computed case."""

import math

import numpy as np
import pytest

from quad_model.frames import STANDARD_GRAVITY_MPS2, quat_from_euler
from rig.autopilots.reference.estimator import DistanceToGround, PositionEstimator
from rig.autopilots.reference.land_detector import LandDetector
from rig.autopilots.reference.navigator import Navigator
from rig.autopilots.reference.params import Parameters
from rig.autopilots.reference.process import range_reading
from rig.mavlink.px4_api import mavlink
from rig.mavlink.sim_messages import distance_sensor

LEVEL = quat_from_euler(0.0, 0.0, 0.0)
LIMITS = (0.05, 25.0)


@pytest.mark.parametrize("quality", [0, 1, 37, 50, 98, 100])
def test_distance_sensor_round_trips_as_px4_reads_it(quality):
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    message = distance_sensor(mav, 1_234_567, distance_m=3.456, signal_quality=quality,
                              min_m=0.05, max_m=25.0)  # fmt: skip
    decoded = mav.parse_char(message.pack(mav))
    assert decoded.orientation == mavlink.MAV_SENSOR_ROTATION_PITCH_270  # PX4: downward
    assert decoded.time_boot_ms == 1234
    reading = range_reading(decoded)
    assert (reading.distance_m, reading.min_m, reading.max_m) == pytest.approx((3.46, 0.05, 25.0))
    assert reading.signal_quality == quality


def test_distance_sensor_refuses_a_quality_out_of_range():
    mav = mavlink.MAVLink(None)
    with pytest.raises(ValueError, match=r"^signal_quality must be 0..100 \(uORB\), not 101$"):
        distance_sensor(mav, 1, distance_m=1.0, signal_quality=101, min_m=0.05, max_m=25.0)


def test_height_above_ground_is_range_times_cos_tilt_and_times_out():
    ground = DistanceToGround()
    tilted = quat_from_euler(math.radians(20.0), math.radians(10.0), 1.0)
    assert ground.update(4.0, 100, LIMITS, tilted, 1_000_000)
    expected = 4.0 * math.cos(math.radians(20.0)) * math.cos(math.radians(10.0))
    assert ground.height(1_000_000) == pytest.approx(expected, abs=1e-12)
    assert ground.height(1_000_000 + DistanceToGround.RANGE_TIMEOUT_US) is not None
    assert ground.height(1_000_001 + DistanceToGround.RANGE_TIMEOUT_US) is None


@pytest.mark.parametrize(
    ("distance_m", "quality", "roll_deg"),
    [(0.04, 100, 0.0), (25.01, 100, 0.0), (3.0, 0, 0.0), (3.0, 100, 46.0)],
    ids=["below min", "beyond max", "quality 0", "tilted past 45 deg"],
)
def test_unusable_readings_are_ignored(distance_m, quality, roll_deg):
    ground = DistanceToGround()
    q = quat_from_euler(math.radians(roll_deg), 0.0, 0.0)
    assert not ground.update(distance_m, quality, LIMITS, q, 0)
    assert ground.height(0) is None


def test_range_aid_pulls_a_wrong_height_onto_the_ground():
    """Baro says 2 m up; once the aid applies, the range (1.0 m above a ground first placed
    at 1.5 m below) wins within a few updates: EKF2_RNG_NOISE 0.1 m against 3.5 m."""
    estimator = PositionEstimator()
    estimator.configure(Parameters())
    at_rest = np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2])
    estimator.fuse_range(1.5, aid=False)  # places the ground 1.5 m under the estimate (0)
    for _ in range(100):
        estimator.predict(at_rest, 0.004)
        estimator.fuse_baro(2.0)
        estimator.fuse_range(1.0, aid=True)
    assert estimator.position_ned_m[2] == pytest.approx(1.5 - 1.0, abs=0.05)


def test_a_gps_origin_after_range_aid_keeps_the_covariance_positive():
    """Regression: set_origin replaced the vertical velocity's variance but kept its
    correlation with the height, which the precise range had made large: P went indefinite
    and the estimate ran away at the first GPS fix."""
    estimator = PositionEstimator()
    estimator.configure(Parameters())
    at_rest = np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2])
    estimator.fuse_range(0.1, aid=False)
    for _ in range(50):
        estimator.predict(at_rest, 0.004)
        estimator.fuse_range(0.1, aid=True)
    estimator.set_origin(47.0, 8.0, 500.0, 200_000, np.zeros(3))
    assert min(np.linalg.eigvalsh(estimator.p[axis]).min() for axis in range(3)) >= 0.0


def test_landing_crawls_below_land_alt3_only_with_a_rangefinder():
    params = Parameters()
    navigator = Navigator(params, lambda *_: np.zeros(3), lambda *_: None, lambda *_: None)
    navigator.home_ned = np.zeros(3)
    navigator.hold_ned = np.array([0.0, 0.0, -0.8])
    position = np.array([0.0, 0.0, -0.8])
    assert navigator.land(position, 0.02).velocity_ned_mps[2] == pytest.approx(0.7)
    crawl = navigator.land(position, 0.02, dist_bottom_m=0.8).velocity_ned_mps[2]
    assert crawl == pytest.approx(0.3)  # MPC_LAND_CRWL below MPC_LAND_ALT3 (1 m)
    # Above ALT3 the rangefinder's height sets the speed: 7.5 m is half way ALT2..ALT1.
    halfway = navigator.land(position, 0.02, dist_bottom_m=7.5).velocity_ned_mps[2]
    assert halfway == pytest.approx(0.7 + 0.5 * (1.5 - 0.7))


def test_ground_contact_waits_for_the_rangefinder_to_read_under_a_metre():
    """With a rangefinder the crawl (0.3 m/s) counts as the commanded descent, and ground
    contact needs its height under 1 m; without one the descent must be MPC_LAND_SPEED."""
    params = Parameters()
    thrust = 0.12 + 0.1 * (0.5 - 0.12)  # minimal
    cases = ((1.2, 0.3, False), (0.1, 0.3, True), (None, 0.3, False), (None, 0.7, True))
    for dist_bottom, descent_sp, lands in cases:
        detector = LandDetector()
        detector.detect_takeoff(-3.0, -1.0)
        landed = any(
            detector.detect_landing(
                params, k * 4000, 0.0, 0.0, descent_sp, thrust, 0.0, dist_bottom
            )
            for k in range(500)
        )
        assert landed is lands, (dist_bottom, descent_sp)
