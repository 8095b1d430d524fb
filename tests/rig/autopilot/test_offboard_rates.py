"""SET_ATTITUDE_TARGET as PX4 decodes it (mavlink_receiver.cpp): the type_mask says whether
the attitude or the body rates are flown; thrust is collective 0..1 either way."""

from collections import deque

import numpy as np
import pytest

from rig.autopilots.reference.gcs import GroundStation
from rig.mavlink.px4_api import mavlink

ATTITUDE_IGNORE = mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
RATES_IGNORE = (
    mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
)


class RecordingController:
    """What GroundStation needs of a flight controller, recording the offboard calls."""

    def __init__(self) -> None:
        self.params = {"MAV_SYS_ID": 1}
        self.status_messages: deque = deque()
        self.mission_events: deque = deque()
        self.calls: list[tuple] = []

    def set_offboard_rates(self, rates, thrust):
        self.calls.append(("rates", tuple(rates), thrust))

    def set_offboard_attitude(self, q, thrust):
        self.calls.append(("attitude", tuple(q), thrust))


def _handle(mask: int, q=(1.0, 0.0, 0.0, 0.0), rates=(0.1, -0.2, 0.3), thrust=0.6):
    controller = RecordingController()
    station = GroundStation(controller, [])
    message = mavlink.MAVLink_set_attitude_target_message(1234, 1, 1, mask, list(q), *rates,
                                                          thrust)  # fmt: skip
    station.handle(None, message)
    return controller.calls, station


def test_attitude_ignored_flies_the_body_rates():
    calls, _ = _handle(ATTITUDE_IGNORE)
    assert calls == [("rates", pytest.approx((0.1, -0.2, 0.3)), pytest.approx(0.6))]


def test_attitude_given_flies_the_attitude_and_ignores_the_rates():
    q = np.array([0.9, 0.1, 0.2, 0.3])
    calls, _ = _handle(RATES_IGNORE, q=tuple(q))
    ((kind, flown, thrust),) = calls
    assert kind == "attitude"
    np.testing.assert_allclose(flown, q / np.linalg.norm(q), rtol=1e-6)  # float32 on the wire
    assert thrust == pytest.approx(0.6)


@pytest.mark.parametrize(
    ("mask", "counter"),
    [
        (ATTITUDE_IGNORE | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE, "unexpected"),
        (ATTITUDE_IGNORE | mavlink.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE, "unexpected"),
    ],
)
def test_neither_a_full_attitude_nor_all_rates_is_counted_not_flown(mask, counter):
    calls, station = _handle(mask)
    assert calls == []
    assert getattr(station, counter) == 1


def test_non_finite_rates_are_malformed():
    calls, station = _handle(ATTITUDE_IGNORE, rates=(float("nan"), 0.0, 0.0))
    assert calls == []
    assert station.malformed == 1
