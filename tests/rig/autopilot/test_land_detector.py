"""PX4's three-stage land detector against hand-computed timings."""

import pytest

from rig.autopilots.reference.land_detector import Hysteresis, LandDetector
from rig.autopilots.reference.params import Parameters

FRAME_US = 4_000
#: MPC_THR_MIN + 0.1·(MPC_THR_HOVER − MPC_THR_MIN) with PX4's defaults 0.12 and 0.5.
MINIMAL_THRUST = 0.12 + 0.1 * (0.5 - 0.12)


def test_hysteresis_needs_the_condition_for_its_delay_and_drops_at_once():
    stage = Hysteresis()
    assert not stage.update(True, 0, 1000)
    assert not stage.update(True, 999, 1000)
    assert stage.update(True, 1000, 1000)
    assert not stage.update(False, 1001, 1000)
    assert not stage.update(True, 1002, 1000)  # the delay starts again


def _touch_down(detector, params, thrust, speed_down_mps=0.0, start_us=0, seconds=3.0):
    """Descent commanded at MPC_LAND_SPEED, the vehicle at rest: the frame landing is seen."""
    for k in range(round(seconds * 1e6 / FRAME_US)):
        t = start_us + k * FRAME_US
        if detector.detect_landing(params, t, speed_down_mps, 0.0, 0.7, thrust, 0.0):
            return t
    return None


def test_landing_is_detected_after_the_three_stages():
    """With descent commanded, no motion and minimal thrust from t = 0, each stage waits a third
    of LNDMC_TRIG_TIME (1 s): ground contact at 1/3 s, maybe landed 1/3 s later, landed at
    1 s (to the 4 ms frame)."""
    params = Parameters()
    detector = LandDetector()
    detector.detect_takeoff(-3.0, -1.0)
    assert not detector.landed
    landed_at_us = _touch_down(detector, params, MINIMAL_THRUST)
    assert landed_at_us == pytest.approx(1_000_000, abs=3 * FRAME_US)
    assert detector.landed


@pytest.mark.parametrize(
    ("thrust", "speed_down_mps", "why"),
    [(0.5, 0.0, "hover thrust"), (MINIMAL_THRUST, 0.3, "still descending"),
     (0.2, 0.0, "low but not minimal thrust")],
)  # fmt: skip
def test_no_landing_while_a_condition_fails(thrust, speed_down_mps, why):
    detector = LandDetector()
    detector.detect_takeoff(-3.0, -1.0)
    assert _touch_down(detector, Parameters(), thrust, speed_down_mps) is None, why
    assert not detector.landed


@pytest.mark.parametrize(("thrust", "contact"), [(0.2, True), (0.34, True), (0.36, False)])
def test_low_thrust_gives_ground_contact_only(thrust, contact):
    """Below 60 % of the thrust range (0.348 with PX4's defaults 0.12 and 0.5: PX4 with a
    valid hover thrust estimate) is ground contact (the controller then cuts thrust); it
    is not landed until the thrust is minimal."""
    params = Parameters()
    detector = LandDetector()
    detector.detect_takeoff(-3.0, -1.0)
    _touch_down(detector, params, thrust, seconds=0.5)
    assert detector.ground_contact == contact
    assert not detector.maybe_landed
