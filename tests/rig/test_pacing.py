"""Real-time pacing: sleeps only, never faster than asked, nothing at ``max``."""

import math

import pytest

from rig.lockstep.pacing import MIN_SLEEP_S, Pacer, parse_speed


class FakeClock:
    """Wall time that moves only when the pacer sleeps or the test says the frame took."""

    def __init__(self):
        self.now = 100.0
        self.sleeps = []

    def clock(self):
        return self.now

    def sleep(self, seconds):
        self.sleeps.append(seconds)
        self.now += seconds


def test_real_time_holds_simulated_time_to_the_wall_clock():
    wall = FakeClock()
    pacer = Pacer(1.0, wall.clock, wall.sleep)
    for frame in range(1, 1001):  # 1 kHz frames that each take 0.2 ms of work
        wall.now += 0.0002
        pacer.wait(frame / 1000)
    assert wall.now - 100.0 == pytest.approx(1.0, abs=MIN_SLEEP_S)
    assert all(s >= MIN_SLEEP_S for s in wall.sleeps)  # no sleep shorter than worth it


def test_half_speed_takes_twice_the_wall_time_and_a_slow_loop_is_not_slowed_further():
    wall = FakeClock()
    pacer = Pacer(0.5, wall.clock, wall.sleep)
    pacer.wait(1.0)
    assert wall.now - 100.0 == pytest.approx(2.0)
    wall.now += 5.0  # the loop fell behind (RTL chips slower than asked)
    pacer.wait(1.5)
    assert wall.sleeps == [pytest.approx(2.0)]


def test_max_never_sleeps():
    wall = FakeClock()
    pacer = Pacer(math.inf, wall.clock, wall.sleep)
    pacer.wait(1000.0)
    assert wall.sleeps == []


@pytest.mark.parametrize(("text", "speed"), [("max", math.inf), ("MAX", math.inf),
                                             ("1", 1.0), ("0.25", 0.25), ("8", 8.0)])  # fmt: skip
def test_speed_text(text, speed):
    assert parse_speed(text) == speed


@pytest.mark.parametrize("text", ["0", "-1", "fast", "nan", "inf", ""])
def test_bad_speed_is_one_line(text):
    with pytest.raises(ValueError, match=r"^--speed .*: expected 'max' or a positive factor"):
        parse_speed(text)


def test_cli_refuses_a_bad_speed(capsys):
    from rig.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(["run", "takeoff_hover_land", "--speed", "0"])
    assert exit_info.value.code == 2
    assert (
        "--speed '0': expected 'max' or a positive factor of real time" in capsys.readouterr().err
    )


def _result(simulated_s, wall_s, chips_us, wait_us):
    from pathlib import Path

    from rig.lockstep.loop import FrameBudget, RunResult
    from rig.mavlink.simulator_link import LinkStats

    frames = round(simulated_s * 1000)
    budget = FrameBudget(40.0, 50.0, chips_us, 70.0, 30.0, wait_us, 30.0, 20.0)
    link = LinkStats(frames_sent=frames, answers=frames, late_answers=frames // 4)
    return RunResult(Path("run"), Path("run/rig.ulg"), None, simulated_s, wall_s, frames,
                     link, budget)  # fmt: skip


def test_a_run_that_could_not_keep_its_speed_says_so_and_where_the_time_went():
    from rig.cli.flight import speed_shortfall

    slow = _result(70.0, 100.0, chips_us=1000.0, wait_us=100.0)
    line = speed_shortfall(slow, 1.0)
    assert line is not None
    assert "could not keep --speed 1: it ran at 0.70x real time" in line
    assert "each 1,000 µs frame took 1,340 µs here, 1,000 of them in the chips" in line
    assert "100 waiting for the autopilot, whose answer came late in 17,500 of 70,000" in line
    assert speed_shortfall(_result(70.0, 70.5, 500.0, 100.0), 1.0) is None  # kept: paced
    assert speed_shortfall(slow, 0.5) is None  # half speed asked, 0.7 achieved
    assert speed_shortfall(slow, math.inf) is None  # as fast as it can: nothing to keep
