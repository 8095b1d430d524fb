"""CommandScript's setpoint tracks: recorded setpoints sent at their times, held between."""

import math

import pytest

from quad_model.environment import GeoPoint
from rig.scenarios.scenario import Arm, Disarm, Land, SetHome, SetpointTrack, Track
from rig.scenarios.script import CommandScript


class RecordingGround:
    """The GroundLink calls a script makes, as plain tuples."""

    def velocity_setpoint(self, velocity, yaw, time_s):
        return ("velocity", tuple(velocity), yaw, round(time_s, 6))

    def rates_setpoint(self, rates, thrust, time_s):
        return ("rates", tuple(rates), thrust, round(time_s, 6))

    def quaternion_setpoint(self, q, thrust, time_s):
        return ("attitude", tuple(q), thrust, round(time_s, 6))

    def offboard(self, setpoints, what):
        return ("offboard", *setpoints)

    def arm(self, arm=True):
        return ("arm", arm)

    def attempt(self, conversation):
        return ("attempt", conversation)

    def land(self):
        return ("land",)

    def set_home(self, home):
        return ("set_home", home)


def _walk(commands, until_s, clock_start_s=0.0, frame_s=0.001):
    script = CommandScript(tuple(commands), RecordingGround(), barrier=True,
                           clock_start_s=clock_start_s)  # fmt: skip
    sent = []
    frame_us = round(frame_s * 1e6)
    for frame in range(round(until_s / frame_s) + 1):
        time_us = frame * frame_us
        sent += [(time_us / 1e6, action.conversation) for action in script.due(time_us)]
    return sent


VELOCITY = SetpointTrack(
    "velocity", (0.0, 0.25, 0.3), ((0.0, 0.0, 0.0, math.nan), (0.0, 0.0, -1.5, 1.7),
                                   (0.5, 0.0, -1.5, 1.7)),
)  # fmt: skip


def test_each_sample_goes_out_at_its_time_and_is_held_with_keep_alives():
    sent = _walk([Track(at_s=0.0, track=VELOCITY)], 0.55, clock_start_s=400.0)
    times = [t for t, _ in sent]
    assert times == [0.0, 0.1, 0.2, 0.25, 0.3, 0.4, 0.5]  # samples, and every 0.1 s between
    values = [conversation[1][1] for _, conversation in sent]
    held, climb, forward = (0.0, 0.0, 0.0), (0.0, 0.0, -1.5), (0.5, 0.0, -1.5)
    assert values == [held, held, held, climb, forward, forward, forward]
    yaws = [conversation[1][2] for _, conversation in sent]
    assert yaws[:3] == [None] * 3  # NaN yaw: not controlled
    assert yaws[3] == 1.7
    stamps = [conversation[1][3] for _, conversation in sent]
    assert stamps[3] == pytest.approx(400.25)  # the autopilot's clock, not the run's


def test_arm_and_disarm_keep_the_stream_a_mode_command_ends_it():
    commands = [
        Arm(at_s=0.0),
        Track(at_s=0.0, track=VELOCITY),
        Disarm(at_s=0.15, may_refuse=True),
        Land(at_s=0.35),
    ]
    sent = _walk(commands, 0.6)
    kinds = [(t, conversation[0]) for t, conversation in sent]
    assert kinds == [(0.0, "arm"), (0.0, "offboard"), (0.1, "offboard"), (0.15, "attempt"),
                     (0.2, "offboard"), (0.25, "offboard"), (0.3, "offboard"),
                     (0.35, "land")]  # fmt: skip


def test_a_replays_home_keeps_the_stream_and_a_refusal_does_not_end_the_run():
    home = GeoPoint(51.9, -85.7, 185.84)
    sent = _walk([Track(at_s=0.0, track=VELOCITY), SetHome(at_s=0.15, home=home)], 0.25)
    kinds = [(t, conversation[0]) for t, conversation in sent]
    assert kinds == [(0.0, "offboard"), (0.1, "offboard"), (0.15, "attempt"),
                     (0.2, "offboard"), (0.25, "offboard")]  # fmt: skip
    assert sent[2][1][1] == ("set_home", home)


def test_a_rates_track_started_mid_way_sends_the_sample_in_force():
    rates = SetpointTrack("rates", (0.0, 0.02, 0.04), ((0.1, 0, 0, 0.5), (0.2, 0, 0, 0.5),
                                                       (0.3, 0, 0, 0.6)))  # fmt: skip
    sent = _walk([Track(at_s=0.03, track=rates)], 0.05)
    assert [(t, c[1][1][0], c[1][2]) for t, c in sent] == [(0.03, 0.2, 0.5), (0.04, 0.3, 0.6)]


def test_a_track_needs_a_known_kind_and_one_value_per_time():
    with pytest.raises(ValueError, match="track kind 'position' is not one of"):
        SetpointTrack("position", (0.0,), ((0.0, 0.0, 0.0, 0.0),))
    with pytest.raises(ValueError, match="one value per time"):
        SetpointTrack("rates", (0.0, 1.0), ((0.0, 0.0, 0.0, 0.5),))
