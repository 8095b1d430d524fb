"""cocotb bench for the PWM capture core: PX4-range pulse trains, one-tick accuracy,
failsafe timeout, and the RTL equal to the TLM model at every probe.

Run from ``test_cosim_pwm.py`` on every simulator, on a core built with the tick and
timeout below (its ``sync`` clock is the tick clock).
"""

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import Timer, with_timeout

from fpga_hdl.chips.pwm_capture.core import CHANNELS, timeout_ticks
from fpga_hdl.chips.pwm_capture.model import ChannelCapture, PwmCaptureModel
from fpga_hdl.verification.pwm_source import CocotbPwmSource
from fpga_hdl.verification.scoreboard import Scoreboard

TICK_HZ = 1e6
TIMEOUT_S = 0.03
COUNTER_BITS = timeout_ticks(TICK_HZ, TIMEOUT_S).bit_length()
#: (width µs, rate Hz) per channel: 900..2100 µs at 50..490 Hz (2100 µs needs <= 476 Hz).
CHANNEL_SPECS = [
    (900, 50),
    (1100, 100),
    (1300, 200),
    (1500, 300),
    (1700, 400),
    (2000, 490),
    (2100, 400),
    (1234.5, 490),
]
RUN_S = 0.045
START_S = 5.3e-6  # mid-tick, after reset


def read(dut) -> list[ChannelCapture]:
    widths, periods = int(dut.width_ticks.value), int(dut.period_ticks.value)
    timeout, mask = int(dut.timeout.value), (1 << COUNTER_BITS) - 1
    return [
        ChannelCapture(
            widths >> (ch * COUNTER_BITS) & mask,
            periods >> (ch * COUNTER_BITS) & mask,
            bool(timeout >> ch & 1),
        )
        for ch in range(CHANNELS)
    ]


@cocotb.test()
async def widths_within_one_tick_and_timeout_when_pulses_stop(dut):
    Clock(dut.clk, round(1e12 / TICK_HZ), unit="ps").start(start_high=True)  # edges at k µs
    dut.rst.value = 1
    source = CocotbPwmSource(dut.pwm__pulses)
    await Timer(500, unit="ns")
    dut.rst.value = 0
    trains = []
    for ch, (width_us, rate_hz) in enumerate(CHANNEL_SPECS):
        period_s, count = 1 / rate_hz, int(RUN_S * rate_hz)
        cocotb.start_soon(
            source.pulses(
                ch,
                width_s=width_us * 1e-6,
                period_s=period_s,
                count=count,
                start_s=START_S - 500e-9,
            )
        )
        trains.append(
            [(START_S + i / rate_hz, START_S + i / rate_hz + width_us * 1e-6) for i in range(count)]
        )
    model = PwmCaptureModel(tick_hz=TICK_HZ, timeout_s=TIMEOUT_S)
    scoreboard = Scoreboard()
    probe_s, probes = 500e-9, 0
    end_s = RUN_S + TIMEOUT_S + 2e-3
    while probe_s < end_s:
        step_us = 997 if probe_s < RUN_S - 3e-3 or probe_s > RUN_S + 1e-3 else 13
        await with_timeout(Timer(step_us * 1000, unit="ns"), 1, "sec")
        probe_s += step_us * 1e-6
        got = read(dut)
        for ch in range(CHANNELS):
            expected = model.capture(trains[ch], at_s=probe_s)
            scoreboard.check(f"channel {ch} at {probe_s * 1e6:.1f} µs", expected, got[ch])
        probes += 1
        if abs(probe_s - (RUN_S - 2e-3)) < 7e-6:
            for ch, (width_us, rate_hz) in enumerate(CHANNEL_SPECS):
                assert not got[ch].timeout
                assert abs(got[ch].width_ticks - width_us * 1e-6 * TICK_HZ) <= 1, (ch, got[ch])
                assert abs(got[ch].period_ticks - TICK_HZ / rate_hz) <= 1, (ch, got[ch])
    assert read(dut) == [ChannelCapture(0, 0, True)] * CHANNELS  # failsafe after the stop
    dut._log.info("%d probes, all channels equal to the model", probes)
