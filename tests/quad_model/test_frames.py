"""Frame conventions against closed-form rotations and PX4's map projection."""

import math

import numpy as np
import pytest

from quad_model import frames


@pytest.mark.parametrize(
    ("roll", "pitch", "yaw", "v_frd", "v_ned"),
    [
        # Facing east (yaw +90°): body forward is east, body right is south.
        (0.0, 0.0, math.pi / 2, [1, 0, 0], [0, 1, 0]),
        (0.0, 0.0, math.pi / 2, [0, 1, 0], [-1, 0, 0]),
        # Nose up 90°: body forward points up (-down).
        (0.0, math.pi / 2, 0.0, [1, 0, 0], [0, 0, -1]),
        # Right wing down 90° (roll +90°): body right points down.
        (math.pi / 2, 0.0, 0.0, [0, 1, 0], [0, 0, 1]),
    ],
)
def test_body_to_ned_closed_form(roll, pitch, yaw, v_frd, v_ned):
    q = frames.quat_from_euler(roll, pitch, yaw)
    np.testing.assert_allclose(frames.body_to_ned(q, np.array(v_frd, float)), v_ned, atol=1e-12)
    np.testing.assert_allclose(frames.ned_to_body(q, np.array(v_ned, float)), v_frd, atol=1e-12)


def test_euler_round_trip_and_composition():
    angles = np.array([0.3, -0.4, 2.5])
    q = frames.quat_from_euler(*angles)
    np.testing.assert_allclose(frames.euler_from_quat(q), angles, atol=1e-12)
    # Z-Y-X: q = q_yaw ⊗ q_pitch ⊗ q_roll.
    composed = frames.quat_multiply(
        frames.quat_from_axis_angle([0, 0, 1], 2.5),
        frames.quat_multiply(
            frames.quat_from_axis_angle([0, 1, 0], -0.4),
            frames.quat_from_axis_angle([1, 0, 0], 0.3),
        ),
    )
    np.testing.assert_allclose(composed, q, atol=1e-12)
    dcm = frames.quat_to_dcm(q)
    np.testing.assert_allclose(dcm @ dcm.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(dcm) == pytest.approx(1.0)


def test_geodetic_projection_closed_form_and_round_trip():
    lat0, lon0, alt0 = 47.397742, 8.545594, 488.0
    # 1 km north is 1000/R rad of latitude on PX4's sphere.
    lat, lon, alt = frames.ned_to_geodetic([1000.0, 0.0, -20.0], lat0, lon0, alt0)
    assert lat - lat0 == pytest.approx(math.degrees(1000.0 / frames.EARTH_RADIUS_M), rel=1e-9)
    assert lon == pytest.approx(lon0, abs=1e-12)
    assert alt == pytest.approx(508.0)
    point = np.array([-350.0, 1234.5, 7.0])
    back = frames.geodetic_to_ned(
        *frames.ned_to_geodetic(point, lat0, lon0, alt0), lat0, lon0, alt0
    )
    np.testing.assert_allclose(back, point, atol=1e-6)


def test_pwm_throttle_mapping():
    np.testing.assert_allclose(
        frames.pwm_to_throttle([900, 1000, 1530, 2000, 2100]), [0, 0, 0.53, 1, 1]
    )
