"""The flight controller flying the test plant in-process (no sockets): takeoff and hold,
attitude-estimate error in hover and through a level-flight step, failsafes."""

import math

import numpy as np
import pytest

from quad_model.frames import quat_to_dcm
from rig.autopilot.flight_controller import FlightController
from rig.autopilot.navigator import NavState
from rig.autopilot.params import Parameters
from tests.rig.autopilot.plant import HOME, QuadPlant, fly


def _attitude_error_rad(controller, plant) -> float:
    return 2 * math.acos(min(abs(float(np.dot(controller.attitude.q, plant.q))), 1.0))


def _tilt_error_rad(controller, plant) -> float:
    z_est, z_true = quat_to_dcm(controller.attitude.q)[:, 2], quat_to_dcm(plant.q)[:, 2]
    return math.acos(min(float(z_est @ z_true), 1.0))


@pytest.fixture(scope="module")
def hovering():
    """Takeoff to 5 m above home, then 5 s of hold; every frame's errors recorded."""
    plant = QuadPlant(np.random.default_rng(7))
    controller = FlightController(Parameters())
    fly(controller, plant, 5.0)  # sensors warm up, gyro calibrated at rest, GPS origin set
    assert controller.takeoff(HOME[2] + 5.0).result == 0
    assert controller.arm().result == 0
    record = []
    fly(controller, plant, 12.0, on_frame=lambda c, p: record.append(
        (p.time_us, p.position.copy(), _attitude_error_rad(c, p), _tilt_error_rad(c, p),
         c.nav_state)))  # fmt: skip
    return controller, plant, record


def test_takeoff_to_5_m_then_holds(hovering):
    """Within 12 s the takeoff completes and switches to hold; over the last 4 s the vehicle
    stays within 0.3 m of 5 m altitude and within 1.0 m horizontally of where it lifted off."""
    controller, _, record = hovering
    assert controller.nav_state == NavState.AUTO_LOITER
    assert not controller.landed
    last = [position for t, position, *_ in record if t >= record[-1][0] - 4_000_000]
    altitudes = np.array([-p[2] for p in last])
    horizontal = np.array([math.hypot(p[0], p[1]) for p in last])
    assert np.abs(altitudes - 5.0).max() < 0.3
    assert horizontal.max() < 1.0


def test_attitude_estimate_error_in_hover(hovering):
    """Tilt error below 0.5° and full attitude error below 3° (heading through the
    magnetometer) over the last 4 s of hover."""
    _, _, record = hovering
    last = [r for r in record if r[0] >= record[-1][0] - 4_000_000]
    assert max(r[3] for r in last) < math.radians(0.5)
    assert max(r[2] for r in last) < math.radians(3.0)


def test_attitude_estimate_error_through_a_level_flight_step(hovering):
    """An offboard position step 15 m north at 5 m altitude: the vehicle tilts up to the
    tilt limit and back; the estimated tilt stays within 2.5° of the truth throughout."""
    controller, plant, _ = hovering
    start = controller.position.position_ned_m.copy()
    target = start + np.array([15.0, 0, 0])
    controller.set_offboard_setpoint(target, np.full(3, np.nan), 0.0, math.nan)
    assert controller.set_mode(NavState.OFFBOARD).result == 0
    worst_tilt, max_tilt = [0.0], [0.0]

    def watch(c, p):
        c.set_offboard_setpoint(target, np.full(3, np.nan), 0.0, math.nan)
        worst_tilt[0] = max(worst_tilt[0], _tilt_error_rad(c, p))
        max_tilt[0] = max(max_tilt[0], math.acos(quat_to_dcm(p.q)[2, 2]))

    fly(controller, plant, 10.0, on_frame=watch)
    assert max_tilt[0] > math.radians(10)  # it really manoeuvred
    assert worst_tilt[0] < math.radians(2.5)
    assert controller.position.position_ned_m[0] - start[0] == pytest.approx(15.0, abs=1.0)
