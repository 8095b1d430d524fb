"""Actuator controls → PWM pulses → capture → throttle, against closed-form timings."""

import numpy as np
import pytest

from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.chips.pwm_capture.model import PwmCaptureModel
from fpga_hdl.top import PWM_RESULT_LATENCY_TICKS as HOST_LATENCY
from quad_model.vehicle import MAX_ROTORS
from rig.chips.pwm import PWM_TIMEOUT_S, Pulse, PwmCapture, PwmOutput, throttle_from_capture


def test_pulses_at_400_hz_with_widths_latched_at_each_period():
    out = PwmOutput(4, 400)
    assert out.period_us == 2500
    out.command([0.0, 0.5, 1.0, 0.25], armed=True)
    first = out.pulses(1001)  # frame 1 ends at 1 ms: one period has started (t = 0)
    assert [(p.channel, p.start_us, p.width_us) for p in first] == [
        (0, 0, 1000), (1, 0, 1500), (2, 0, 2000), (3, 0, 1250),
    ]  # fmt: skip
    out.command([0.7] * 4, armed=True)
    assert out.pulses(2001) == []  # no new period before 2.5 ms: the command waits
    assert {p.width_us for p in out.pulses(3001)} == {1700}  # latched at t = 2.5 ms
    out.command([0.7] * 4, armed=False)
    assert {p.width_us for p in out.pulses(5001)} == {1000}  # disarmed: PWM_MAIN_DIS
    assert len(out.pulses(1_005_001, dropped={1, 2})) == 2 * 400  # 1 s, two channels


def test_pwm_rate_outside_esc_range_is_refused():
    with pytest.raises(ValueError, match=r"pwm_hz must be within 50\.\.490 Hz .*got 1000"):
        PwmOutput(4, 1000)


def test_capture_of_the_last_pulses_equals_the_model_over_the_whole_history():
    rng = np.random.default_rng(5)
    model = PwmCaptureModel(tick_hz=1e6, timeout_s=PWM_TIMEOUT_S, latency_ticks=HOST_LATENCY)
    capture = PwmCapture(1)
    history, start_us = [], 0
    for _ in range(300):
        gap_us = 2500 if rng.random() > 0.03 else int(rng.integers(50_000, 250_000))  # dropouts
        start_us += gap_us
        width_us = int(rng.integers(900, 2101))
        history.append((start_us / 1e6, (start_us + width_us) / 1e6))
        now_us = start_us + int(rng.integers(0, 2400))
        widths, timed_out = capture.capture([Pulse(0, start_us, width_us)], now_us)
        full = model.capture(history, at_s=now_us / 1e6)
        assert widths[0] == full.width_ticks  # 1 tick = 1 µs
        assert timed_out[0] == full.timeout


def test_capture_on_the_frame_grid_equals_the_whole_history():
    """Frames every 1 ms, pulses every 2.5 ms whose falls land on frame times, dropouts."""
    model = PwmCaptureModel(tick_hz=1e6, timeout_s=PWM_TIMEOUT_S, latency_ticks=HOST_LATENCY)
    out, capture, history = PwmOutput(1, 400), PwmCapture(1), []
    for frame in range(1, 1500):
        now_us = frame * 1000
        out.command([(frame // 7 % 5) / 4], armed=True)  # widths 1000, 1250, ... 2000 µs
        dropped = {0} if 600 <= frame < 800 else set()
        pulses = out.pulses(now_us + 1, dropped)
        history += [(p.start_us / 1e6, (p.start_us + p.width_us) / 1e6) for p in pulses]
        widths, timed_out = capture.capture(pulses, now_us)
        full = model.capture(history, at_s=now_us / 1e6)
        assert (widths[0], timed_out[0]) == (full.width_ticks, full.timeout), f"frame {frame}"


@pytest.mark.parametrize("flown_s", [0, 32, 64, 1000, 3600])
def test_a_pulse_reads_its_exact_width_first_at_its_fall_plus_the_latency(flown_s):
    """Whole-µs pulses on the 1 µs tick, as the RTL layers replay them: each width is read
    exactly, first at its fall plus the host port's latency, after any time of flight
    (seconds as floats lose the µs from 32 s on, where a tick-late edge once showed)."""
    capture = PwmCapture(1)
    start_us = flown_s * 1_000_000
    previous = None
    for period in range(2000):
        width_us = 1000 + 7 * (period % 143)  # widths 1000..1994 µs, each new
        pulse = Pulse(0, start_us, width_us)
        seen_us = start_us + width_us + HOST_LATENCY
        before = capture.capture([pulse], seen_us - 1)[0][0]
        assert before == (0.0 if previous is None else previous), start_us
        widths, timed_out = capture.capture([], seen_us)
        assert (widths[0], timed_out[0]) == (width_us, False), start_us
        previous, start_us = width_us, start_us + 2500


def test_width_measured_within_one_tick_and_timeout_after_100_ms():
    capture = PwmCapture(2)
    pulses = [Pulse(0, k * 2500, 1500) for k in range(8)]
    widths, timed_out = capture.capture(pulses, 20_000)
    assert widths[0] == pytest.approx(1500, abs=1)
    assert timed_out == (False, True)  # channel 1 never pulsed
    widths, timed_out = capture.capture([], 17_500 + 100_000 + 10)
    assert timed_out[0]
    assert throttle_from_capture(widths, timed_out).tolist() == [0.0, 0.0]
    assert throttle_from_capture([1500.0, 2000.0], [False, False]).tolist() == [0.5, 1.0]


def test_the_capture_core_has_a_channel_for_every_rotor_the_model_flies():
    """Motor i is output and capture channel i, so the largest vehicle must fit the core."""
    assert MAX_ROTORS <= CHANNELS
