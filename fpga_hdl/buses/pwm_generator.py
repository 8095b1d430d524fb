"""Autopilot-side PWM generator: the flight controller's timer outputs driving the ESCs.

Like an STM32 timer in PWM mode 1 with preload (what PX4's ``pwm_out`` programs): one
counter per generator counts ``0 .. period_ticks - 1`` and every channel is high while
the counter is below its width. Widths are *preloaded*: a width written mid-period takes
effect at the next period start (the timer's update event), so a pulse is never cut
short or stretched by a write, and software writes each width once per frame. A width of
0 keeps a channel low: no pulse at all, as a dropped-out output. The whole generator runs
on its own clock (one tick per cycle), so the simulator pays ``tick_hz`` cycles per
second for all eight channels and nothing per pulse edge.
"""

from __future__ import annotations

from amaranth.build import Platform
from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.signatures import PWM, PWM_CHANNELS

__all__ = ["PwmGenerator"]


class PwmGenerator(wiring.Component):
    """Eight PWM outputs with a common period, widths in ticks of the ``sync`` clock.

    Parameters
    ----------
    counter_bits : int
        Width of the period and width registers (16 bits: periods up to 65.5 ms at 1 µs).

    Attributes
    ----------
    period_ticks : In(counter_bits)
        Period of every channel; 0 stops the generator (all outputs low).
    width_ticks : In(ArrayLayout(unsigned(counter_bits), 8))
        Pulse width per channel, taken at each period start.
    pwm : Out(PWM)
        ``pulses``: the outputs, one bit per channel.
    """

    def __init__(self, *, counter_bits: int = 16) -> None:
        if not (isinstance(counter_bits, int) and counter_bits >= 2):
            raise ValueError(f"counter_bits must be an integer >= 2, not {counter_bits!r}")
        self.counter_bits = counter_bits
        super().__init__(
            {
                "period_ticks": In(counter_bits),
                "width_ticks": In(data.ArrayLayout(counter_bits, PWM_CHANNELS)),
                "pwm": Out(PWM),
            }
        )

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        count = Signal(self.counter_bits)
        channels = range(PWM_CHANNELS)
        active = [Signal(self.counter_bits, name=f"active_width_{ch}") for ch in channels]
        running = self.period_ticks != 0
        # Update event: each period starts at count 0 with the widths written by then.
        at_start = count == 0
        widths = [Mux(at_start, self.width_ticks[ch], active[ch]) for ch in range(PWM_CHANNELS)]
        with m.If(at_start):
            m.d.sync += [active[ch].eq(self.width_ticks[ch]) for ch in range(PWM_CHANNELS)]
        with m.If(~running | (count + 1 >= self.period_ticks)):
            m.d.sync += count.eq(0)
        with m.Else():
            m.d.sync += count.eq(count + 1)
        m.d.sync += self.pwm.pulses.eq(Cat(*((count < width) & running for width in widths)))
        return m
