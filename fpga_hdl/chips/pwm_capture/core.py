"""Eight-channel PWM capture: pulse width, period and a timeout flag per channel, in ticks."""

import math

from amaranth.build import Platform
from amaranth.hdl import Module, Mux, Signal, Value
from amaranth.lib import data, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.by_event import least, skip_members
from fpga_hdl.buses.signatures import PWM, PWM_CHANNELS

__all__ = ["CHANNELS", "LATENCY_TICKS", "SKIP_BITS", "PwmCapture", "timeout_ticks"]

CHANNELS = PWM_CHANNELS
#: Two flip-flops re-time the asynchronous PWM inputs.
SYNC_STAGES = 2
#: Clock edges from the one that first samples a PWM edge to the one that updates the
#: results: the synchroniser's second stage, then the result registers (the edge detector
#: between them is combinational).
LATENCY_TICKS = SYNC_STAGES
#: Width of a skippable core's ``skip`` and ``quiet`` (ticks one edge may stand for).
SKIP_BITS = 16
_QUIET_MAX = (1 << SKIP_BITS) - 1


def timeout_ticks(tick_hz: float, timeout_s: float) -> int:
    """The timeout in whole ticks (at least 2); rejects nonsense with an exact message."""
    if not (isinstance(tick_hz, int | float) and math.isfinite(tick_hz) and tick_hz > 0):
        raise ValueError(f"tick_hz must be a positive frequency in Hz, not {tick_hz!r}")
    if not (isinstance(timeout_s, int | float) and math.isfinite(timeout_s) and timeout_s > 0):
        raise ValueError(f"timeout_s must be a positive duration in s, not {timeout_s!r}")
    return max(2, round(timeout_s * tick_hz))


class PwmCapture(wiring.Component):
    """Measure the servo/ESC PWM the autopilot drives, one counter per channel.

    Why its own clock: the core counts in ticks, and the cheapest clock that resolves one
    tick is the tick itself. Its ``sync`` domain is meant to run at ``tick_hz`` (the top
    renames it to a slow ``pwm`` domain), so a 400 Hz motor PWM costs ``tick_hz`` cycles
    per simulated second, not the system clock's. At the default 1 MHz a tick is 1 µs,
    the unit PX4 uses for PWM. The results change once per pulse, so a reader in another
    domain samples them with the usual two-flop synchroniser, at worst one pulse late.

    Definitions, per channel, counted on the re-timed input: ``width_ticks`` is the
    high time of the last complete pulse (rising to falling edge), ``period_ticks`` the
    time between its last two rising edges. ``timeout`` is 1 from reset, and again once
    ``timeout_s`` passes without a rising edge (pulses stopped, or the line stuck high
    or low): width and period then read 0, so a reader that ignores the flag still sees
    a zero command. It clears at the falling edge of the next complete pulse.

    Parameters
    ----------
    tick_hz : float
        Frequency of the ``sync`` domain; one tick per cycle.
    timeout_s : float
        Time without a rising edge after which a channel is flagged (and zeroed).

    Attributes
    ----------
    pwm : In(PWM)
        ``pulses``: the PWM inputs, one bit per channel (asynchronous).
    width_ticks : Out(ArrayLayout(unsigned(counter_bits), 8))
        Pulse width per channel, in ticks.
    period_ticks : Out(ArrayLayout(unsigned(counter_bits), 8))
        Pulse period per channel, in ticks; 0 until two rising edges are seen.
    timeout : Out(8)
        Per channel: no pulse for ``timeout_s`` (or none yet since reset).

    With ``skippable`` (a simulation build: the compiled co-simulation advances the
    capture clock by event, not tick by tick) the core also has:

    skip : In(SKIP_BITS)
        Ticks beyond one that the next edge stands for (0: an ordinary edge).
    quiet : Out(SKIP_BITS)
        How many ticks the next edge may stand for: through them the core only counts
        (no edge in its pipeline, no timeout due), provided its input has held still for
        the synchroniser's ``SYNC_STAGES`` edges, which only the driver of the pins can
        know. 0: the next edge must be an ordinary one.

    Without it (synthesis) neither port exists and the design is the plain counter.
    """

    def __init__(
        self, *, tick_hz: float = 1e6, timeout_s: float = 0.1, skippable: bool = False
    ) -> None:
        self.timeout_ticks = timeout_ticks(tick_hz, timeout_s)
        self.tick_hz = float(tick_hz)
        self.timeout_s = float(timeout_s)
        self.counter_bits = self.timeout_ticks.bit_length()
        self.skippable = skippable
        counts = data.ArrayLayout(self.counter_bits, CHANNELS)
        members = {
            "pwm": In(PWM),
            "width_ticks": Out(counts),
            "period_ticks": Out(counts),
            "timeout": Out(CHANNELS, init=(1 << CHANNELS) - 1),
        }
        if skippable:
            members |= skip_members(SKIP_BITS)
        super().__init__(members)

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        level = Signal(CHANNELS)
        m.submodules.sync_pwm = FFSynchronizer(self.pwm.pulses, level, stages=SYNC_STAGES)
        previous = Signal(CHANNELS)
        m.d.sync += previous.eq(level)
        # The ticks this edge stands for, and per channel how many more are quiet.
        ticks = 1 + self.skip if self.skippable else 1
        quiet: list[Value] = []

        for ch in range(CHANNELS):
            rise = level[ch] & ~previous[ch]
            fall = ~level[ch] & previous[ch]
            # Ticks since the last rising edge; saturates at the timeout.
            since_rise = Signal(self.counter_bits, name=f"since_rise_{ch}")
            armed = Signal(name=f"armed_{ch}")  # a rising edge seen since the timeout
            width, period = self.width_ticks[ch], self.period_ticks[ch]
            timeout = self.timeout[ch]

            with m.If(since_rise < self.timeout_ticks):
                if self.skippable:  # saturates at the timeout, as tick by tick
                    counted = since_rise + ticks
                    m.d.sync += since_rise.eq(
                        Mux(counted < self.timeout_ticks, counted, self.timeout_ticks)
                    )
                else:
                    m.d.sync += since_rise.eq(since_rise + 1)
            with m.If(rise):
                m.d.sync += [since_rise.eq(1), armed.eq(1)]
                with m.If(armed):
                    m.d.sync += period.eq(since_rise)
            with m.Elif(armed & (since_rise == self.timeout_ticks)):
                m.d.sync += [armed.eq(0), timeout.eq(1), width.eq(0), period.eq(0)]
            with m.Elif(fall & armed):
                m.d.sync += [width.eq(since_rise), timeout.eq(0)]
            if self.skippable:  # an armed channel times out at the edge seeing the count
                left = self.timeout_ticks - since_rise
                quiet.append(Mux(armed & (left < _QUIET_MAX), left, _QUIET_MAX))
        if self.skippable:
            m.d.comb += self.quiet.eq(Mux(level == previous, least(*quiet), 0))
        return m
