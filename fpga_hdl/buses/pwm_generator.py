"""Autopilot-side PWM generator: the flight controller's timer outputs driving the ESCs.

Like an STM32 timer in PWM mode 1 with preload (what PX4's ``pwm_out`` programs): one
counter per generator counts ``0 .. period_ticks - 1`` and every channel is high while
the counter is below its width. Widths are *preloaded*: a width written mid-period takes
effect at the next period start (the timer's update event), so a pulse is never cut
short or stretched by a write, and software writes each width once per frame. A width of
0 keeps a channel low: no pulse at all, as a dropped-out output. The whole generator runs
on its own clock (one tick per cycle), so the simulator pays ``tick_hz`` cycles per
second for all eight channels and nothing per pulse edge.

A simulation that runs many ticks at a time may let one edge stand for several
(``skip``) while nothing but the counter moves: ``quiet`` says how many, counting
only once the outputs have held still for ``settle_edges`` edges (the synchronisers of
the core that samples them), so the reader's pipeline is at rest too.
"""

from __future__ import annotations

from amaranth.build import Platform
from amaranth.hdl import Cat, Module, Mux, Signal, Value
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.by_event import least, skip_members
from fpga_hdl.buses.signatures import PWM, PWM_CHANNELS

__all__ = ["PwmGenerator"]


class PwmGenerator(wiring.Component):
    """Eight PWM outputs with a common period, widths in ticks of the ``sync`` clock.

    Parameters
    ----------
    counter_bits : int
        Width of the period and width registers (16 bits: periods up to 65.5 ms at 1 µs).
    settle_edges : int
        Edges the outputs must have held still before ``quiet`` is ever above 0.

    Attributes
    ----------
    period_ticks : In(counter_bits)
        Period of every channel; 0 stops the generator (all outputs low).
    width_ticks : In(ArrayLayout(unsigned(counter_bits), 8))
        Pulse width per channel, taken at each period start.
    pwm : Out(PWM)
        ``pulses``: the outputs, one bit per channel.
    skip : In(counter_bits)
        Ticks beyond one that the next edge stands for (0: an ordinary edge).
    quiet : Out(counter_bits)
        How many ticks the next edge may stand for with no output changing and no period
        starting (0: the next edge must be an ordinary one).
    """

    def __init__(self, *, counter_bits: int = 16, settle_edges: int = 0) -> None:
        if not (isinstance(counter_bits, int) and counter_bits >= 2):
            raise ValueError(f"counter_bits must be an integer >= 2, not {counter_bits!r}")
        if not (isinstance(settle_edges, int) and settle_edges >= 0):
            raise ValueError(f"settle_edges must be an integer >= 0, not {settle_edges!r}")
        self.counter_bits = counter_bits
        self.settle_edges = settle_edges
        super().__init__(
            {
                "period_ticks": In(counter_bits),
                "width_ticks": In(data.ArrayLayout(counter_bits, PWM_CHANNELS)),
                "pwm": Out(PWM),
                **skip_members(counter_bits),
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
            m.d.sync += count.eq(count + 1 + self.skip)
        pulses = Cat(*((count < width) & running for width in widths))
        m.d.sync += self.pwm.pulses.eq(pulses)
        self._quiet(m, count, active, running, pulses)
        return m

    def _quiet(
        self, m: Module, count: Signal, active: list[Signal], running: Value, pulses: Value
    ) -> None:
        """``quiet``: edges before the next period start or output change, once the
        outputs have held still for ``settle_edges`` edges (``pulses``: their next value).
        A high output holds while the count stays below its width, so for
        ``width - count`` more edges; a low one stays low until the period ends."""
        outputs = self.pwm.pulses
        held = Signal(range(self.settle_edges + 1))  # edges since the outputs last changed
        with m.If(pulses != outputs):
            m.d.sync += held.eq(0)
        with m.Elif(held < self.settle_edges):
            m.d.sync += held.eq(held + 1)
        limit = (1 << self.counter_bits) - 1
        left: list[Value] = [self.period_ticks - 1 - count]  # edges before the wrap
        left += [Mux(outputs[ch], width - count, limit) for ch, width in enumerate(active)]
        settled = running & (count != 0) & (count < self.period_ticks) & (held == self.settle_edges)
        m.d.comb += self.quiet.eq(Mux(settled, least(*left), 0))
