# amaranth: UnusedElaboratable=no
"""amaranth.sim unit tests of the PWM capture core, against closed-form widths and the model."""

import math

import numpy as np
import pytest
from amaranth.sim import Simulator

from fpga_hdl.chips.pwm_capture.core import CHANNELS, LATENCY_TICKS, PwmCapture
from fpga_hdl.chips.pwm_capture.model import ChannelCapture, PwmCaptureModel
from fpga_hdl.verification.scoreboard import Scoreboard

#: A slow tick keeps the cycle-level Python simulation short; the cocotb tests use 1 MHz.
TICK_HZ = 100e3
TIMEOUT_S = 0.03


def level_at(pulses: list[tuple[float, float]], t: float) -> int:
    return int(any(rise <= t < fall for rise, fall in pulses))


def run_core(trains: list[list[tuple[float, float]]], ticks: int, probe_every: int):
    """Drive ``trains`` (edge times in ticks) tick by tick; read results every few ticks."""
    dut = PwmCapture(tick_hz=TICK_HZ, timeout_s=TIMEOUT_S)
    sim = Simulator(dut)
    sim.add_clock(1 / TICK_HZ)
    probes = {}

    async def bench(ctx):
        for tick in range(ticks):
            ctx.set(
                dut.pwm.pulses, sum(level_at(train, tick) << ch for ch, train in enumerate(trains))
            )
            await ctx.tick()  # clock edge number `tick` samples that level
            if tick % probe_every == 0 or tick == ticks - 1:
                widths, periods = ctx.get(dut.width_ticks), ctx.get(dut.period_ticks)
                timeout = ctx.get(dut.timeout)
                probes[tick] = [
                    ChannelCapture(int(widths[ch]), int(periods[ch]), bool(timeout >> ch & 1))
                    for ch in range(CHANNELS)
                ]

    sim.add_testbench(bench)
    sim.run()
    return probes


def pulse_train(start: float, width: float, period: float, count: int):
    return [(start + i * period, start + i * period + width) for i in range(count)]


def test_constructor_rejects_nonsense():
    with pytest.raises(ValueError, match=r"^tick_hz must be a positive frequency in Hz, not 0$"):
        PwmCapture(tick_hz=0)
    with pytest.raises(ValueError, match=r"^timeout_s must be a positive duration in s, not nan$"):
        PwmCapture(timeout_s=math.nan)


def test_widths_and_periods_closed_form_and_timeout_after_pulses_stop():
    # Widths 900..2100 µs at 50..490 Hz, at 100 kHz ticks: 90..210 ticks, edges mid-tick.
    # (A 490 Hz period is 2041 µs, so 2100 µs pulses run at 400 Hz.)
    specs = [
        (900, 50),
        (1100, 100),
        (1300, 200),
        (1500, 300),
        (1700, 400),
        (2000, 490),
        (2100, 400),  # a 490 Hz period is 2041 µs: 2100 µs pulses need <= 476 Hz
        (1500, 50),
    ]
    trains = []
    for width_us, rate_hz in specs:
        width, period = width_us * 1e-6 * TICK_HZ, TICK_HZ / rate_hz
        trains.append(pulse_train(3.5, width, period, math.ceil(0.045 * rate_hz)))
    ticks = int(0.045 * TICK_HZ) + int(TIMEOUT_S * TICK_HZ) + 10
    probes = run_core(trains, ticks, probe_every=97)

    mid = int(0.044 * TICK_HZ)  # pulses still running everywhere
    mid = max(t for t in probes if t <= mid)
    for ch, (width_us, rate_hz) in enumerate(specs):
        got = probes[mid][ch]
        assert not got.timeout, (ch, mid, got)
        # Within one tick of the true width and period (quantization by the sampling).
        assert abs(got.width_ticks - width_us * 1e-6 * TICK_HZ) <= 1
        assert abs(got.period_ticks - TICK_HZ / rate_hz) <= 1
    last = probes[ticks - 1]
    assert all(c == ChannelCapture(0, 0, True) for c in last)  # pulses stopped: failsafe


def test_rtl_equals_model_for_random_trains_with_gaps():
    rng = np.random.default_rng(7)
    ticks = 9000
    trains = []
    for _ in range(CHANNELS):
        period = float(rng.uniform(TICK_HZ / 490, TICK_HZ / 50))
        width = float(rng.uniform(0.1, 0.9) * period)
        pulses = pulse_train(float(rng.uniform(0, 50)) + 0.5, width, period, 100)
        gap_at = float(rng.uniform(1000, 5000))  # pulses stop, then resume
        gap = float(rng.choice([0.0, TIMEOUT_S * TICK_HZ * 1.2]))
        kept = [(r, f) for r, f in pulses if f < gap_at]
        kept += [(r + gap, f + gap) for r, f in pulses if r > gap_at]
        trains.append([(r, f) for r, f in kept if f < ticks])
    probes = run_core(trains, ticks, probe_every=37)
    model = PwmCaptureModel(tick_hz=TICK_HZ, timeout_s=TIMEOUT_S)
    scoreboard, timeouts_seen = Scoreboard(), 0
    for tick, captures in probes.items():
        for ch, got in enumerate(captures):
            pulses_s = [(r / TICK_HZ, f / TICK_HZ) for r, f in trains[ch]]
            expected = model.capture(pulses_s, at_s=tick / TICK_HZ)
            scoreboard.check(f"channel {ch} at tick {tick}", expected, got)
            timeouts_seen += got.timeout and tick > 100
    assert timeouts_seen > 0  # the gaps really exercised the timeout


def test_model_latency_and_a_pulse_too_short_to_sample():
    model = PwmCaptureModel(tick_hz=1e6, timeout_s=0.1)
    pulses = [(10.5e-6, 20.5e-6), (30.2e-6, 30.4e-6), (40.5e-6, 45.5e-6)]
    # The falling edge at 20.5 µs is sampled at tick 21 and acted on LATENCY_TICKS later.
    assert model.capture(pulses[:1], at_s=(21 + LATENCY_TICKS - 1) * 1e-6).timeout
    assert model.capture(pulses[:1], at_s=(21 + LATENCY_TICKS) * 1e-6) == ChannelCapture(
        10, 0, False
    )
    # The 0.2 µs pulse falls between two samples and is invisible.
    assert model.capture(pulses, at_s=60e-6) == ChannelCapture(5, 30, False)
    with pytest.raises(ValueError, match=r"^pulses must be increasing"):
        model.capture([(2.0, 1.0)], at_s=3.0)


def test_a_later_reader_sees_every_result_the_same_ticks_later():
    """``latency_ticks`` delays the whole result set: widths, periods and the timeout
    (which runs from the delayed rise). Closed form at 1 µs ticks: a 10 µs pulse from
    10.5 µs, its fall sampled at tick 21; the core shows it at 23, a reader 3 ticks
    behind the sampling at 24; the timeout (0.1 ms) follows the rise the same way."""
    core = PwmCaptureModel(tick_hz=1e6, timeout_s=1e-4)
    reader = PwmCaptureModel(tick_hz=1e6, timeout_s=1e-4, latency_ticks=LATENCY_TICKS + 1)
    pulses = [(10.5e-6, 20.5e-6)]
    assert reader.capture(pulses, at_s=23e-6).timeout
    assert reader.capture(pulses, at_s=24e-6) == ChannelCapture(10, 0, False)
    # The rise sampled at tick 11: core timeout at 11 + 2 + 100, the reader's a tick on.
    assert not reader.capture(pulses, at_s=113e-6).timeout
    assert reader.capture(pulses, at_s=114e-6) == ChannelCapture(0, 0, True)
    rng = np.random.default_rng(3)
    trains = [pulse_train(float(rng.uniform(0, 5)), 3.3, 7.1, 30) for _ in range(3)]
    for train in trains:
        train_s = [(r * 1e-6, f * 1e-6) for r, f in train]
        for tick in range(1, 260):
            assert reader.capture(train_s, at_s=tick * 1e-6) == core.capture(
                train_s, at_s=(tick - 1) * 1e-6
            ), tick


def test_model_refuses_a_latency_below_the_cores():
    with pytest.raises(
        ValueError, match=r"^latency_ticks must be a whole number of ticks >= the core's 2, not 1$"
    ):
        PwmCaptureModel(latency_ticks=1)
