"""Autopilot-side I2C controller: the flight controller MCU's I2C peripheral, in gateware.

Why it exists: the I2C target (``i2c_target``) oversamples the bus with the system clock,
so that clock runs through every transfer anyway; a Python controller on top of it also
wakes up several times per bit. This controller runs the whole combined transfer in the
simulator: software loads the address and bytes, asks once and waits for one acknowledge.

Behaviour per NXP UM10204 rev. 7 (section 3.1 and table 10): START, 7-bit address with
R/W, data bytes each followed by an acknowledge bit, repeated START between the write
and the read part (as PX4's ``I2C::transfer`` does), the controller ACKing every read
byte but the last, which it NACKs, then STOP and t_BUF of free bus before it reports
the transfer done. A NACK of the address or of a written byte ends the transfer with a
STOP and is reported with the byte's index. Every duration is the table 10 minimum of
the chosen mode, stretched to its nominal rate (:func:`timing_for`) and rounded *up* to
whole system cycles, so the bus never runs faster than asked. Data changes one system
cycle after SCL falls (a controller may use 0 ns hold; one cycle keeps it clear of the
edge), and SDA is sampled in the middle of SCL high. No clock stretching: the IST8310
never stretches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from amaranth.build import Platform
from amaranth.hdl import Cat, Const, Module, Mux, Shape, Signal, Value, ValueLike
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.by_event import skip_members
from fpga_hdl.buses.i2c_target import FAST_MODE, STANDARD_MODE, I2cTiming
from fpga_hdl.buses.transactions import check_clock_hz

__all__ = ["I2cBitCycles", "I2cController", "controller_rate_hz", "timing_for"]

#: The two rates the controller runs, as PX4's I2C buses do: Standard- and Fast-mode.
RATES_HZ = (100e3, 400e3)


def timing_for(scl_hz: float) -> I2cTiming:
    """Spec-minimum timing of the mode that covers ``scl_hz``, stretched to that rate.

    The slack beyond t_LOW + t_HIGH is split evenly between the two phases.
    """
    check_clock_hz("scl_hz", scl_hz)
    for mode, top_hz in ((STANDARD_MODE, 100e3), (FAST_MODE, 400e3)):
        if scl_hz <= top_hz:
            slack_ns = max(0.0, 1e9 / scl_hz - mode.t_low_ns - mode.t_high_ns)
            return replace(
                mode, t_low_ns=mode.t_low_ns + slack_ns / 2, t_high_ns=mode.t_high_ns + slack_ns / 2
            )
    raise ValueError(f"scl_hz {scl_hz:g} is above Fast-mode (400 kHz), which the IST8310 tops at")


def controller_rate_hz(scl_hz: float) -> float:
    """The controller's rate for a request: the fastest of :data:`RATES_HZ` not above it."""
    check_clock_hz("scl_hz", scl_hz)
    if scl_hz > RATES_HZ[-1]:
        raise ValueError(f"scl_hz {scl_hz:g} is above Fast-mode (400 kHz), the controller's top")
    if scl_hz < RATES_HZ[0]:
        raise ValueError(f"scl_hz {scl_hz:g} is below the controller's slowest rate, 100 kHz")
    return max(rate for rate in RATES_HZ if rate <= scl_hz)


def _cycles(duration_ns: float, clk_hz: float) -> int:
    return max(1, math.ceil(duration_ns * clk_hz / 1e9 - 1e-9))


@dataclass(frozen=True)
class I2cBitCycles:
    """One mode's UM10204 durations in whole system cycles (each covers its minimum)."""

    low: int
    high: int
    hd_sta: int
    su_sta: int
    su_sto: int
    buf: int
    hd_dat: int

    @classmethod
    def for_rate(cls, scl_hz: float, sys_clk_hz: float) -> I2cBitCycles:
        t = timing_for(scl_hz)
        cycles = cls(
            low=_cycles(t.t_low_ns, sys_clk_hz),
            high=_cycles(t.t_high_ns, sys_clk_hz),
            hd_sta=_cycles(t.t_hd_sta_ns, sys_clk_hz),
            su_sta=_cycles(t.t_su_sta_ns, sys_clk_hz),
            su_sto=_cycles(t.t_su_sto_ns, sys_clk_hz),
            buf=_cycles(t.t_buf_ns, sys_clk_hz),
            hd_dat=1,
        )
        if cycles.low - cycles.hd_dat < _cycles(t.t_su_dat_ns, sys_clk_hz) or cycles.high < 2:
            raise ValueError(f"sys_clk_hz {sys_clk_hz:g} is too slow for I2C at {scl_hz:g} Hz")
        return cycles

    @property
    def bit(self) -> int:
        return self.low + self.high


class I2cController(wiring.Component):
    """I2C controller for combined write/read transfers, 100 and 400 kHz.

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the ``sync`` domain; every duration is counted in its cycles.
    write_depth, read_depth : int
        Longest write part (data bytes after the address) and read part.

    Attributes
    ----------
    request : In(1)
        Toggle to ask for a transfer (pending while it differs from ``acknowledge``);
        the other inputs must hold until the acknowledge.
    acknowledge : Out(1)
        Set equal to ``request`` once STOP and t_BUF are over.
    busy : Out(1)
        A transfer is in progress.
    address : In(7)
        Target address.
    write_len : In(range(write_depth + 1)), read_len : In(range(read_depth + 1))
        Bytes to write, then (after a repeated START) bytes to read. With both zero the
        address is sent with W and nothing else (a probe).
    tx : In(8 * write_depth)
        Bytes to write, byte ``i`` in bits ``8i .. 8i + 7``.
    rx : Out(8 * read_depth)
        Bytes read, same order.
    fast : In(1)
        1: Fast-mode at 400 kHz; 0: Standard-mode at 100 kHz.
    nack : Out(1)
        The last transfer ended on a NACK.
    nack_index : Out(range(write_depth + 1))
        Which byte was refused: 0 the address, ``i`` the written byte ``i``.
    scl : Out(1)
        SCL (the controller drives it; no target stretches it).
    sda_o : Out(1)
        1 releases SDA, 0 pulls it low (open drain).
    sda_i : In(1)
        SDA as seen on the bus (the wired-AND of every driver).
    skip : In(:attr:`quiet_bits`), quiet : Out(:attr:`quiet_bits`)
        ``skippable`` only (the compiled co-simulation's build, never synthesis): between
        two actions only the duration counter moves, so ``quiet`` says how many coming
        edges that is, and the next edge stands for ``1 + skip`` cycles
        (:mod:`fpga_hdl.buses.by_event`).
    """

    def __init__(self, *, sys_clk_hz: float, write_depth: int = 8, read_depth: int = 16,
                 skippable: bool = False) -> None:  # fmt: skip
        for name, depth in (("write_depth", write_depth), ("read_depth", read_depth)):
            if not (isinstance(depth, int) and depth >= 1):
                raise ValueError(f"{name} must be a positive integer, not {depth!r}")
        self.sys_clk_hz = float(sys_clk_hz)
        self.standard = I2cBitCycles.for_rate(RATES_HZ[0], sys_clk_hz)
        self.fast_mode = I2cBitCycles.for_rate(RATES_HZ[1], sys_clk_hz)
        self.write_depth = write_depth
        self.read_depth = read_depth
        self.skippable = skippable
        longest = max(*vars(self.standard).values(), *vars(self.fast_mode).values())
        #: The duration counter's width: ``skip`` and ``quiet`` have it too.
        self.quiet_bits = Shape.cast(range(longest + 1)).width
        super().__init__(
            {
                "request": In(1),
                "acknowledge": Out(1),
                "busy": Out(1),
                "address": In(7),
                "write_len": In(range(write_depth + 1)),
                "read_len": In(range(read_depth + 1)),
                "tx": In(8 * write_depth),
                "rx": Out(8 * read_depth),
                "fast": In(1),
                "nack": Out(1),
                "nack_index": Out(range(write_depth + 1)),
                "scl": Out(1, init=1),
                "sda_o": Out(1, init=1),
                "sda_i": In(1),
            }
            | (skip_members(self.quiet_bits) if skippable else {})
        )

    def transfer_cycles(self, write_len: int, read_len: int, *, fast: bool = True) -> int:
        """System cycles from the request to the acknowledge, for cycle budgets."""
        c = self.fast_mode if fast else self.standard
        write_part = write_len > 0 or read_len == 0
        frames = (1 + write_len if write_part else 0) + (1 + read_len if read_len else 0)
        restart = c.low + c.su_sta + c.hd_sta if write_part and read_len else 0
        return 1 + c.hd_sta + 9 * frames * c.bit + restart + c.low + c.su_sto + c.buf

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        fast = Signal()

        def cycles(field: str) -> Value:
            return Mux(fast, getattr(self.fast_mode, field), getattr(self.standard, field))

        wait = Signal(self.quiet_bits)
        cycles_now = 1 + self.skip if self.skippable else 1  # what this edge stands for
        write_len = Signal.like(self.write_len)
        read_len = Signal.like(self.read_len)
        address = Signal(7)
        tx = Signal.like(self.tx)
        byte = Signal(8)  # byte being sent (shifted left) or received (shifted in)
        bit = Signal(range(10))  # 0..7 data bits, 8 the acknowledge bit, 9 byte over
        index = Signal(range(max(self.write_depth, self.read_depth) + 1))  # byte in its part
        sending = Signal()  # 1: this byte goes to the target; 0: it comes from it
        addressing = Signal()  # the byte is the address byte
        reading = Signal()  # the read part's address has been sent or is being sent
        acked = Signal()

        def after(state: str, duration: ValueLike, *actions: object) -> None:
            """Leave for ``state`` (which lasts ``duration`` cycles) once ``wait`` is 0."""
            with m.If(wait == 0):
                m.d.sync += [*actions, wait.eq(duration - 1)]
                m.next = state
            with m.Else():
                m.d.sync += wait.eq(wait - cycles_now)

        def load(value: ValueLike, *, send: bool, is_address: bool = False) -> None:
            m.d.sync += [
                byte.eq(value),
                bit.eq(0),
                sending.eq(send),
                addressing.eq(is_address),
            ]

        bit_level = Mux(
            bit == 8,
            Mux(sending, 1, index + 1 == read_len),  # release for the target's ACK; NACK last
            Mux(sending, byte[7], 1),
        )

        with m.FSM() as fsm:
            with m.State("IDLE"), m.If(self.request != self.acknowledge):
                write_first = (self.write_len != 0) | (self.read_len == 0)
                m.d.sync += [
                    fast.eq(self.fast),
                    write_len.eq(self.write_len),
                    read_len.eq(self.read_len),
                    address.eq(self.address),
                    tx.eq(self.tx),
                    index.eq(0),
                    reading.eq(~write_first),
                    self.nack.eq(0),
                    self.sda_o.eq(0),  # START: SDA falls while SCL is high
                    wait.eq(Mux(self.fast, self.fast_mode.hd_sta, self.standard.hd_sta) - 1),
                ]
                load(Cat(~write_first, self.address), send=True, is_address=True)
                m.next = "START_HOLD"
            with m.State("START_HOLD"):  # t_HD;STA, then SCL falls
                after("BIT_HOLD", cycles("hd_dat"), self.scl.eq(0))
            with m.State("BIT_HOLD"):  # SCL low: hold the old SDA, then put the bit out
                after("BIT_LOW", cycles("low") - cycles("hd_dat"), self.sda_o.eq(bit_level))
            with m.State("BIT_LOW"):  # SDA set up, SCL rises
                after("BIT_HIGH", cycles("high") // 2, self.scl.eq(1))
            with m.State("BIT_HIGH"):  # sample SDA in the middle of SCL high
                with m.If(wait == 0):
                    with m.If(bit == 8):
                        m.d.sync += acked.eq(~self.sda_i)
                    with m.Elif(sending):
                        m.d.sync += byte.eq(byte << 1)
                    with m.Else():
                        m.d.sync += byte.eq(Cat(self.sda_i, byte[:7]))
                after("BIT_END", cycles("high") - cycles("high") // 2, bit.eq(bit + 1))
            with m.State("BIT_END"):  # SCL falls: next bit, next byte, repeated START or STOP
                after("BIT_HOLD", cycles("hd_dat"), self.scl.eq(0))
                with m.If((wait == 0) & (bit == 9)):
                    with m.If(sending & ~acked):
                        m.d.sync += [
                            self.nack.eq(1),
                            self.nack_index.eq(Mux(addressing, 0, index + 1)),
                        ]
                        m.next = "STOP_HOLD"
                    with m.Elif(~sending):  # a byte was read
                        m.d.sync += self.rx.word_select(index, 8).eq(byte)
                        with m.If(index + 1 < read_len):
                            m.d.sync += index.eq(index + 1)
                            load(0, send=False)
                        with m.Else():
                            m.next = "STOP_HOLD"
                    with m.Elif(reading):  # the read address was acknowledged
                        m.d.sync += index.eq(0)
                        load(0, send=False)
                    with m.Else():  # write part: the address or byte ``index`` acknowledged
                        following = Mux(addressing, 0, index + 1)
                        with m.If(following < write_len):
                            m.d.sync += index.eq(following)
                            load(tx.word_select(following, 8), send=True)
                        with m.Elif(read_len != 0):
                            m.d.sync += reading.eq(1)
                            load(Cat(Const(1, 1), address), send=True, is_address=True)
                            m.next = "RESTART_HOLD"
                        with m.Else():
                            m.next = "STOP_HOLD"
            with m.State("RESTART_HOLD"):  # SCL low: release SDA
                after("RESTART_LOW", cycles("low") - cycles("hd_dat"), self.sda_o.eq(1))
            with m.State("RESTART_LOW"):
                after("RESTART_SETUP", cycles("su_sta"), self.scl.eq(1))
            with m.State("RESTART_SETUP"):  # t_SU;STA, then SDA falls: repeated START
                after("START_HOLD", cycles("hd_sta"), self.sda_o.eq(0))
            with m.State("STOP_HOLD"):  # SCL low: pull SDA low
                after("STOP_LOW", cycles("low") - cycles("hd_dat"), self.sda_o.eq(0))
            with m.State("STOP_LOW"):
                after("STOP_SETUP", cycles("su_sto"), self.scl.eq(1))
            with m.State("STOP_SETUP"):  # t_SU;STO, then SDA rises: STOP
                after("BUS_FREE", cycles("buf"), self.sda_o.eq(1))
            with m.State("BUS_FREE"):  # t_BUF before the next START may come
                after("IDLE", 1, self.acknowledge.eq(self.request))
        m.d.comb += self.busy.eq(~fsm.ongoing("IDLE"))
        if self.skippable:  # every state waits out ``wait`` before it acts; idle, a request
            idle = Mux(self.request != self.acknowledge, 0, (1 << self.quiet_bits) - 1)
            m.d.comb += self.quiet.eq(Mux(self.busy, wait, idle))
        return m
