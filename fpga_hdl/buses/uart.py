"""UART 8N1 transmitter and receiver with a run-time baud divider.

Clocked by their ``sync`` domain: in SensorTop that is the GPS receiver's ``uart`` domain,
a UART crystal every supported rate divides exactly. A bit lasts ``divider`` cycles,
``divider = round(clk_hz / baud)``. The rate error that rounding leaves (none on such a
crystal) is what the far end must tolerate; :func:`baud_error` gives it and
:data:`MAX_BAUD_ERROR` is the budget a divider must meet (see there).
"""

from amaranth.build import Platform
from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.by_event import skip_members

#: Largest transmitter rate error accepted for a divider: 2 %. A receiver that samples
#: mid-bit loses sync when the error accumulated to the stop bit (9.5 bits) reaches about
#: half a bit, 5 %; an STM32 USART (PX4's flight controllers) is specified at 3.75 % total
#: with 16x oversampling. 2 % on our side leaves the rest to the other clock.
MAX_BAUD_ERROR = 0.02
#: Fewest cycles per bit: :class:`UartRx` sees an edge :data:`RX_DELAY_CYCLES` late and
#: samples half a divider after that, so the sample must stay well inside the bit.
MIN_DIVIDER = 8
#: Divider counter width: enough for 9600 baud at 100 MHz.
DIVIDER_BITS = 14
#: Largest ``quiet`` of a skippable :class:`UartTx` or :class:`UartRx`: "nothing to do
#: until an input changes". A skippable one (the compiled co-simulation's build, never
#: synthesis) says in ``quiet`` how many coming edges move nothing but its bit timer, and
#: takes ``skip``: the next edge stands for ``1 + skip`` cycles (``skip < quiet``), so a
#: byte costs a few edges instead of ten bit times of cycles.
QUIET_MAX = (1 << DIVIDER_BITS) - 1
#: Cycles :class:`UartRx` adds to a byte's nine and a half bit times before its strobe:
#: the line passes two synchroniser flip-flops and the edge detector's register before
#: the start bit is seen (checked cycle-exact against the RTL in test_native_harness).
RX_DELAY_CYCLES = 3


def divider_for(clk_hz: float, baud: int) -> int:
    """Clock cycles per bit for ``baud``; refused when the error exceeds the budget."""
    if not clk_hz > 0 or baud <= 0:
        raise ValueError(f"need a positive clock and baud rate, not {clk_hz!r}, {baud!r}")
    divider = round(clk_hz / baud)
    if divider >= 1 << DIVIDER_BITS:
        raise ValueError(
            f"{baud} baud needs a divider of {divider}; at most {(1 << DIVIDER_BITS) - 1}"
        )
    if divider < MIN_DIVIDER:
        raise ValueError(
            f"{baud} baud at {clk_hz:g} Hz needs a divider of {divider}; at least {MIN_DIVIDER}"
        )
    error = baud_error(clk_hz, baud)
    if abs(error) > MAX_BAUD_ERROR:
        raise ValueError(
            f"{baud} baud at {clk_hz:g} Hz is off by {error:+.2%} (divider {divider}); "
            f"the budget is ±{MAX_BAUD_ERROR:.0%}"
        )
    return divider


def line_cycles(byte_count: int, divider: int) -> int:
    """Clock cycles from the first start bit's falling edge of ``byte_count`` bytes sent
    back to back by :class:`UartTx` to :class:`UartRx`'s strobe of the last byte: ten bits
    per byte before it, then the last byte's nine bits and half (the stop bit is sampled
    mid-bit) and the receiver's synchroniser and edge detector (:data:`RX_DELAY_CYCLES`)."""
    if byte_count == 0:
        return 0
    return (byte_count - 1) * 10 * divider + 9 * divider + divider // 2 + RX_DELAY_CYCLES


def cycles_to_us(cycles: int, clk_hz: float) -> int:
    """``cycles`` of ``clk_hz`` in whole µs, rounded up (a byte is there after it)."""
    return -(-cycles * 1_000_000 // round(clk_hz))


def baud_error(clk_hz: float, baud: int) -> float:
    """Relative rate error of the transmitted bits: actual / nominal - 1."""
    return clk_hz / round(clk_hz / baud) / baud - 1


class UartTx(wiring.Component):
    """8N1 transmitter. A byte offered with ``valid`` while ``ready`` is 1 is taken; one
    offered in the last cycle of a stop bit starts its start bit in the next cycle, so
    back-to-back bytes have no idle gap.

    Attributes
    ----------
    tx : Out(1)
        The line (idle high).
    divider : In(DIVIDER_BITS)
        Cycles per bit; change it only while ``busy`` is 0.
    data : In(8), valid : In(1), ready : Out(1)
        The byte stream.
    busy : Out(1)
        A frame is on the line.
    skip : In(DIVIDER_BITS), quiet : Out(DIVIDER_BITS)
        ``skippable`` only (see :data:`QUIET_MAX`).
    """

    def __init__(self, *, skippable: bool = False) -> None:
        self.skippable = skippable
        members = {
            "tx": Out(1, init=1),
            "divider": In(DIVIDER_BITS),
            "data": In(8),
            "valid": In(1),
            "ready": Out(1),
            "busy": Out(1),
        }
        super().__init__(members | (skip_members(DIVIDER_BITS) if skippable else {}))

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        shift = Signal(9)  # data bits then the stop bit, LSB first
        bits_left = Signal(range(11))  # bit periods left including the one on the line
        timer = Signal(DIVIDER_BITS)
        ending = (bits_left == 1) & (timer == 0)
        m.d.comb += [
            self.busy.eq(bits_left != 0),
            self.ready.eq((bits_left == 0) | ending),
        ]
        cycles = 1 + self.skip if self.skippable else 1
        if self.skippable:  # the edges before the next bit edge, or a byte taken
            idle = Mux(self.valid, 0, QUIET_MAX)
            m.d.comb += self.quiet.eq(Mux(bits_left != 0, timer, idle))
        with m.If(self.valid & self.ready):
            m.d.sync += [
                self.tx.eq(0),  # start bit
                shift.eq(Cat(self.data, 1)),
                bits_left.eq(10),
                timer.eq(self.divider - 1),
            ]
        with m.Elif(bits_left != 0):
            with m.If(timer == 0):
                m.d.sync += [
                    self.tx.eq(shift[0] | (bits_left == 1)),
                    shift.eq(Cat(shift[1:], 1)),
                    bits_left.eq(bits_left - 1),
                    timer.eq(self.divider - 1),
                ]
            with m.Else():
                m.d.sync += timer.eq(timer - cycles)
        return m


class UartRx(wiring.Component):
    """8N1 receiver: a falling edge after idle starts a frame, bits are sampled mid-bit
    (half a divider after the edge, then one divider apart), and a low stop bit drops the
    byte (``frame_error``). The line passes two synchroniser flip-flops first.

    Attributes
    ----------
    rx : In(1)
        The line (asynchronous).
    divider : In(DIVIDER_BITS)
        Cycles per bit.
    data : Out(8), stb : Out(1)
        A received byte and its one-cycle strobe.
    frame_error : Out(1)
        One cycle: a frame ended with a low stop bit; its byte was dropped.
    busy : Out(1)
        A frame is being received.
    skip : In(DIVIDER_BITS), quiet : Out(DIVIDER_BITS)
        ``skippable`` only (see :data:`QUIET_MAX`).
    """

    def __init__(self, *, skippable: bool = False) -> None:
        self.skippable = skippable
        members = {
            "rx": In(1, init=1),
            "divider": In(DIVIDER_BITS),
            "data": Out(8),
            "stb": Out(1),
            "frame_error": Out(1),
            "busy": Out(1),
        }
        super().__init__(members | (skip_members(DIVIDER_BITS) if skippable else {}))

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        meta, line, last = Signal(init=1), Signal(init=1), Signal(init=1)
        m.d.sync += [meta.eq(self.rx), line.eq(meta), last.eq(line)]
        timer = Signal(DIVIDER_BITS)
        bit = Signal(range(10))  # 0 start, 1..8 data, 9 stop
        shift = Signal(8)
        cycles = 1 + self.skip if self.skippable else 1
        if self.skippable:  # the synchroniser settled, no strobe to clear: the next sample
            settled = (self.rx == meta) & (meta == line) & (line == last)
            still = settled & ~self.stb & ~self.frame_error
            m.d.comb += self.quiet.eq(Mux(still, Mux(self.busy, timer, QUIET_MAX), 0))
        m.d.sync += [self.stb.eq(0), self.frame_error.eq(0)]
        with m.If(~self.busy), m.If(last & ~line):  # falling edge: the start bit began
            m.d.sync += [self.busy.eq(1), bit.eq(0), timer.eq((self.divider >> 1) - 1)]
        with m.Elif(timer != 0):
            m.d.sync += timer.eq(timer - cycles)
        with m.Else():
            m.d.sync += [timer.eq(self.divider - 1), bit.eq(bit + 1)]
            with m.If(bit == 0), m.If(line):  # a glitch, not a start bit
                m.d.sync += self.busy.eq(0)
            with m.Elif(bit == 9):
                m.d.sync += self.busy.eq(0)
                with m.If(line):
                    m.d.sync += [self.data.eq(shift), self.stb.eq(1)]
                with m.Else():
                    m.d.sync += self.frame_error.eq(1)
            with m.Else():
                m.d.sync += shift.eq(Cat(shift[1:], line))
        return m
