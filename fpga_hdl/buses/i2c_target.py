"""Generic I2C target (slave) engine, per NXP UM10204 (I2C-bus specification, rev. 7).

The engine handles the bus: input synchronisers, the t_SP spike filter, START / repeated
START / STOP detection, 7-bit address match with ACK (or NACK by silence), byte shifting
in both directions with ACK/NACK per byte. A chip core on top of it only sees bytes: the
bytes the controller wrote (``write_stb``) and a request for the next byte to send
(``read_stb``). Register pointers and side effects belong to the chip.
"""

import math
from dataclasses import dataclass

from amaranth.build import Platform
from amaranth.hdl import Assert, Cat, Const, Module, Signal, Value, ValueLike
from amaranth.lib import data, enum, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from fpga_hdl.buses.signatures import BUS_FAULT, I2C

__all__ = [
    "FAST_MODE",
    "STANDARD_MODE",
    "TARGET_SDA_HOLD_NS",
    "I2cTarget",
    "I2cTargetChecker",
    "I2cTiming",
    "TargetSampling",
    "i2c_chip_members",
    "settle_i2c_chip",
]


@dataclass(frozen=True)
class I2cTiming:
    """Bus timing of one I2C speed mode, in nanoseconds.

    The module constants hold the specification limits (UM10204 rev. 7, table 10,
    "Characteristics of the SDA and SCL bus lines"). A controller model generates these
    durations; tests replace single fields to probe the target at or beyond the limits.

    Every field except ``t_vd_dat_max_ns`` and ``t_sp_max_ns`` is a minimum.
    """

    #: SCL LOW period t_LOW.
    t_low_ns: float
    #: SCL HIGH period t_HIGH.
    t_high_ns: float
    #: Hold time of a (repeated) START: SDA falls, then SCL may fall (t_HD;STA).
    t_hd_sta_ns: float
    #: Set-up time of a repeated START: SCL high before SDA falls (t_SU;STA).
    t_su_sta_ns: float
    #: Data set-up time: SDA stable before SCL rises (t_SU;DAT).
    t_su_dat_ns: float
    #: Data hold time: SDA stable after SCL falls (t_HD;DAT; 0 for a controller).
    t_hd_dat_ns: float
    #: Set-up time of a STOP: SCL high before SDA rises (t_SU;STO).
    t_su_sto_ns: float
    #: Bus free time between a STOP and the next START (t_BUF).
    t_buf_ns: float
    #: Maximum data valid time: SCL falls until a transmitter's SDA is valid (t_VD;DAT).
    t_vd_dat_max_ns: float
    #: Widest spike the input filter must suppress (t_SP; 0 for Standard-mode).
    t_sp_max_ns: float

    @property
    def scl_hz(self) -> float:
        """SCL frequency when the controller runs at exactly t_LOW + t_HIGH per bit."""
        return 1e9 / (self.t_low_ns + self.t_high_ns)


#: Standard-mode (up to 100 kHz), UM10204 table 10.
STANDARD_MODE = I2cTiming(
    t_low_ns=4700,
    t_high_ns=4000,
    t_hd_sta_ns=4000,
    t_su_sta_ns=4700,
    t_su_dat_ns=250,
    t_hd_dat_ns=0,
    t_su_sto_ns=4000,
    t_buf_ns=4700,
    t_vd_dat_max_ns=3450,
    t_sp_max_ns=0,
)

#: Fast-mode (up to 400 kHz), UM10204 table 10.
FAST_MODE = I2cTiming(
    t_low_ns=1300,
    t_high_ns=600,
    t_hd_sta_ns=600,
    t_su_sta_ns=600,
    t_su_dat_ns=100,
    t_hd_dat_ns=0,
    t_su_sto_ns=600,
    t_buf_ns=1300,
    t_vd_dat_max_ns=900,
    t_sp_max_ns=50,
)

#: UM10204 table 10 note 2: a device must internally provide at least 300 ns of SDA hold
#: after SCL falls, to bridge the undefined region of the falling edge.
TARGET_SDA_HOLD_NS = 300

#: Two flip-flops re-time the asynchronous bus pins into ``sync``.
SYNC_STAGES = 2


@dataclass(frozen=True)
class TargetSampling:
    """How the target samples the bus at a given ``sync`` clock, derived once.

    ``filter_samples`` (N) equal samples change a filtered line: no spike shorter than
    t_SP can fill N samples when ``N = ceil(t_SP * sys_clk_hz) + 1``. ``hold_cycles``
    pads the SCL-to-SDA delay up to the 300 ns internal hold time.
    """

    sys_clk_hz: float
    filter_samples: int
    hold_cycles: int

    @classmethod
    def for_clock(cls, sys_clk_hz: float) -> "TargetSampling":
        """Sampling for ``sys_clk_hz``; rejects a clock too slow to meet Fast-mode."""
        if not (isinstance(sys_clk_hz, int | float) and math.isfinite(sys_clk_hz)):
            raise ValueError(f"sys_clk_hz must be a positive frequency in Hz, not {sys_clk_hz!r}")
        if sys_clk_hz <= 0:
            raise ValueError(f"sys_clk_hz must be a positive frequency in Hz, not {sys_clk_hz!r}")
        filter_samples = _cycles_covering(FAST_MODE.t_sp_max_ns, sys_clk_hz) + 1
        hold_cycles = max(
            0, _cycles_covering(TARGET_SDA_HOLD_NS, sys_clk_hz) - _pipeline(filter_samples)
        )
        sampling = cls(float(sys_clk_hz), filter_samples, hold_cycles)
        worst_ns = sampling.scl_to_sda_ns[1]
        if worst_ns > FAST_MODE.t_vd_dat_max_ns:
            raise ValueError(
                f"sys_clk_hz {sys_clk_hz:g} is too slow for Fast-mode: SDA would be valid "
                f"{worst_ns:.0f} ns after SCL falls, t_VD;DAT allows "
                f"{FAST_MODE.t_vd_dat_max_ns:.0f} ns"
            )
        return sampling

    @property
    def scl_to_sda_ns(self) -> tuple[float, float]:
        """Shortest and longest delay from SCL falling on the wire to the target's SDA.

        The edge lands anywhere within the cycle before it is first sampled, hence a
        one-cycle spread.
        """
        period_ns = 1e9 / self.sys_clk_hz
        cycles = _pipeline(self.filter_samples) + self.hold_cycles
        return cycles * period_ns, (cycles + 1) * period_ns


def _cycles_covering(duration_ns: float, clk_hz: float) -> int:
    """Whole clock cycles that cover ``duration_ns`` (float noise below 1 ppb ignored)."""
    return math.ceil(duration_ns * clk_hz / 1e9 - 1e-9)


def _pipeline(filter_samples: int) -> int:
    """Cycles from the first clock edge that samples an SCL edge to SDA changing.

    Synchroniser, N-sample window, filtered register, edge detector feeding the FSM
    register, then the SDA register.
    """
    return SYNC_STAGES + filter_samples + 1


#: :class:`I2cTarget`'s ports (a skippable one adds ``settled``).
_TARGET_MEMBERS: dict[str, wiring.Member] = {
    "i2c": In(I2C),
    "fault": In(BUS_FAULT),
    "start": Out(1),
    "stop": Out(1),
    "busy": Out(1),
    "write_stb": Out(1),
    "write_data": Out(8),
    "read_stb": Out(1),
    "read_data": In(8),
}


def i2c_chip_members(layout: data.Layout, *, skippable: bool) -> dict[str, wiring.Member]:
    """The ports of a chip core on the I2C bus (an :class:`I2cTarget` and its registers):
    the bus, the host port's sample, strobe, pending flag, time and fault inputs, and with
    ``skippable`` the core's ``settled`` (:func:`settle_i2c_chip`)."""
    members: dict[str, wiring.Member] = {
        "i2c": In(I2C),
        "sample": In(layout),
        "sample_stb": In(1),
        "sample_pending": Out(1),
        "now_us": In(32),
        "fault": In(BUS_FAULT),
    }
    return members | ({"settled": Out(1)} if skippable else {})


def settle_i2c_chip(m: Module, chip: wiring.Component, target: "I2cTarget",
                    latch: wiring.Component) -> None:  # fmt: skip
    """Drive a skippable chip core's ``settled``: its target is settled and its sample
    latch (:func:`fpga_hdl.host.host_port.chip_sample_latch`) neither copies nor is
    offered a sample. Its registers change only on the target's strobes and the latch's
    copy, and what it compares with ``now_us`` is combinational (the time holds while the
    bus runs alone), so the coming edges change nothing."""
    m.d.comb += chip.settled.eq(target.settled & ~latch.copying & ~chip.sample_stb)


# amaranth is untyped here, so mypy checks shape= against object.__init_subclass__; amaranth's
# enum metaclass takes it
class _State(enum.Enum, shape=3):  # type: ignore[call-arg]
    IDLE = 0  # not addressed: wait for START
    ADDRESS = 1  # shifting in the address byte
    ADDRESS_ACK = 2  # driving the ACK of our address
    WRITE = 3  # shifting in a data byte from the controller
    WRITE_ACK = 4  # driving the ACK of a received data byte
    READ = 5  # shifting out a data byte
    READ_ACK = 6  # listening for the controller's ACK/NACK


class I2cTarget(wiring.Component):
    """I2C target engine with a fixed 7-bit address (UM10204 sections 3.1 and 3.2).

    Why this sampling scheme: the engine oversamples SCL and SDA with the ``sync`` clock
    and filters both with the same N-sample filter. Equal delay on both lines keeps their
    order, so START/STOP and data are told apart exactly as on the wire. N is the
    smallest count that no spike shorter than t_SP (50 ns) can fill:
    ``N = ceil(t_SP * sys_clk_hz) + 1``. The lowest clock that still meets Fast-mode
    (SDA valid within t_VD;DAT = 900 ns of SCL falling, with the 300 ns internal hold)
    is about 7 MHz. 10 MHz is the recommended rate: N = 2, 25 cycles per Fast-mode bit,
    about 2,400 cycles for a PX4 magnetometer read. Every cycle is simulated, and faster
    clocks only add cycles.

    Parameters
    ----------
    address : int
        7-bit target address, 0x08..0x77 (UM10204 table 4 reserves the rest).
    sys_clk_hz : float
        Frequency of the ``sync`` domain.
    assertions : bool
        Bind an :class:`I2cTargetChecker`: the protocol properties below as ``Assert``
        statements on the ``sync`` clock, which ``amaranth.sim`` raises on and a formal
        tool can prove. Off by default: an ``Assert`` becomes a ``$check`` cell, and the
        product's Verilog must not change.

        - the target changes SDA only while SCL is low (UM10204 3.1.3), but for the
          release at a START or STOP;
        - it pulls SDA only while addressed (``busy``);
        - only in an ACK or read-data phase, or within the hold time leaving one.

    Attributes
    ----------
    i2c : In(I2C)
        The bus (:data:`~fpga_hdl.buses.signatures.I2C`): SCL and SDA as seen on the bus
        (the wired-AND of every driver, this one included); ``sda_oe`` = 1 pulls SDA low.
    fault : In(BUS_FAULT)
        While ``mute`` is 1 the target never drives SDA: no ACK, no data; it looks
        absent. ``flip`` is XORed into every data byte the target sends.
    start : Out(1)
        One-cycle strobe: a START or repeated START was seen (any address).
    stop : Out(1)
        One-cycle strobe: a STOP was seen.
    busy : Out(1)
        1 from the ACK of this target's address until the next STOP. A chip holds its
        data registers steady while it is 1, so one transaction reads one sample.
    write_stb : Out(1)
        One-cycle strobe: ``write_data`` holds a byte the controller wrote (and we ACKed).
    write_data : Out(8)
        The byte received with ``write_stb``.
    read_stb : Out(1)
        One-cycle strobe: the engine took ``read_data`` to send it. The chip advances its
        register pointer and applies read side effects on this strobe.
    read_data : In(8)
        Next byte to send, presented by the chip before the engine asks for it.
    settled : Out(1)
        ``skippable`` only (the compiled co-simulation's build, never synthesis): the
        bus pins have passed every synchroniser and filter stage, no edge or START/STOP is
        pending and no SDA change waits out its hold time, so the coming edges change
        nothing here until SCL or SDA changes.
    """

    def __init__(self, *, address: int, sys_clk_hz: float, assertions: bool = False,
                 skippable: bool = False) -> None:  # fmt: skip
        if not isinstance(address, int) or not 0x08 <= address <= 0x77:
            raise ValueError(f"I2C address must be a 7-bit address in 0x08..0x77, not {address!r}")
        self.address = address
        self.sampling = TargetSampling.for_clock(sys_clk_hz)
        self.assertions = assertions
        self.skippable = skippable
        super().__init__(_TARGET_MEMBERS | ({"settled": Out(1)} if skippable else {}))

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()

        scl, scl_settled = self._filtered(m, self.i2c.scl, "scl")
        sda, sda_settled = self._filtered(m, self.i2c.sda_i, "sda")
        scl_prev = Signal(init=1)
        sda_prev = Signal(init=1)
        m.d.sync += [scl_prev.eq(scl), sda_prev.eq(sda)]
        scl_rise = scl & ~scl_prev
        scl_fall = ~scl & scl_prev
        start_cond = scl & scl_prev & sda_prev & ~sda
        stop_cond = scl & scl_prev & ~sda_prev & sda

        state = Signal(_State)
        shift = Signal(8)
        bit_count = Signal(range(9))
        reading = Signal()  # R/W bit of the addressing byte
        acked = Signal()  # the controller ACKed the byte just sent
        sda_drive = Signal()  # 1 = pull SDA low
        drive_next = Signal()  # level for sda_drive once the hold time has passed
        hold = Signal(range(self.sampling.hold_cycles + 1))
        hold_pending = Signal()

        m.d.comb += [
            self.i2c.sda_oe.eq(sda_drive & ~self.fault.mute),
            self.start.eq(start_cond),
            self.stop.eq(stop_cond),
            self.write_data.eq(shift),
        ]

        # SDA changes only after SCL has fallen and the internal hold time has passed.
        with m.If(hold_pending):
            with m.If(hold == 0):
                m.d.sync += [sda_drive.eq(drive_next), hold_pending.eq(0)]
            with m.Else():
                m.d.sync += hold.eq(hold - 1)

        def drive_after_fall(pull_low: ValueLike) -> None:
            m.d.sync += [
                drive_next.eq(pull_low),
                hold.eq(self.sampling.hold_cycles),
                hold_pending.eq(1),
            ]

        def send_next_byte() -> None:
            m.d.comb += self.read_stb.eq(1)
            byte = self.read_data ^ self.fault.flip
            m.d.sync += [
                state.eq(_State.READ),
                shift.eq(Cat(Const(0, 1), byte[:7])),
                bit_count.eq(1),
            ]
            drive_after_fall(~byte[7])

        with m.If(start_cond | stop_cond):
            m.d.sync += [sda_drive.eq(0), hold_pending.eq(0), bit_count.eq(0)]
            with m.If(start_cond):
                m.d.sync += state.eq(_State.ADDRESS)
            with m.Else():
                m.d.sync += [state.eq(_State.IDLE), self.busy.eq(0)]
        with m.Else(), m.Switch(state):
            with m.Case(_State.ADDRESS, _State.WRITE):
                with m.If(scl_rise):
                    m.d.sync += [shift.eq(Cat(sda, shift[:7])), bit_count.eq(bit_count + 1)]
                with m.If(scl_fall & (bit_count == 8)):
                    with m.If(state == _State.WRITE):
                        m.d.comb += self.write_stb.eq(1)
                        m.d.sync += state.eq(_State.WRITE_ACK)
                        drive_after_fall(1)
                    with m.Elif((shift[1:] == self.address) & ~self.fault.mute):
                        m.d.sync += [
                            state.eq(_State.ADDRESS_ACK),
                            reading.eq(shift[0]),
                            self.busy.eq(1),
                        ]
                        drive_after_fall(1)
                    with m.Else():
                        # Not our address: stay silent (NACK) until the next START.
                        m.d.sync += state.eq(_State.IDLE)
            with m.Case(_State.ADDRESS_ACK, _State.WRITE_ACK), m.If(scl_fall):
                with m.If(reading):
                    send_next_byte()
                with m.Else():
                    m.d.sync += [state.eq(_State.WRITE), bit_count.eq(0)]
                    drive_after_fall(0)
            with m.Case(_State.READ), m.If(scl_fall):
                with m.If(bit_count == 8):
                    m.d.sync += state.eq(_State.READ_ACK)
                    drive_after_fall(0)
                with m.Else():
                    m.d.sync += [shift.eq(shift << 1), bit_count.eq(bit_count + 1)]
                    drive_after_fall(~shift[7])
            with m.Case(_State.READ_ACK):
                with m.If(scl_rise):
                    m.d.sync += acked.eq(~sda)
                with m.If(scl_fall):
                    with m.If(acked):
                        send_next_byte()
                    with m.Else():
                        # UM10204 3.1.6: a NACK ends the read; SDA stays released so
                        # the controller can send STOP or a repeated START.
                        m.d.sync += state.eq(_State.IDLE)

        if self.skippable:
            m.d.comb += self.settled.eq(
                scl_settled & sda_settled
                & (scl == scl_prev) & (sda == sda_prev) & ~hold_pending
            )  # fmt: skip
        if self.assertions:
            m.submodules.checker = checker = I2cTargetChecker()
            drive_phase = (
                (state == _State.ADDRESS_ACK) | (state == _State.WRITE_ACK) | (state == _State.READ)
            )
            m.d.comb += [
                checker.scl.eq(scl),
                checker.start_stop.eq(start_cond | stop_cond),
                checker.sda_drive.eq(sda_drive),
                checker.sda_oe.eq(self.i2c.sda_oe),
                checker.busy.eq(self.busy),
                checker.drive_phase.eq(drive_phase),
                checker.hold_pending.eq(hold_pending),
            ]
        return m

    def _filtered(self, m: Module, pin: Signal, name: str) -> tuple[Signal, Value]:
        """Re-time ``pin`` and suppress pulses shorter than t_SP (N equal samples rule).

        Also whether every stage holds the pin's level (always 0 unless ``skippable``): the
        synchroniser's own stages are hidden in it, so a skippable build keeps a copy of
        them, reset-less and initialised alike, to see a pulse still inside it.
        """
        synced = Signal(init=1, name=f"{name}_sync")
        m.submodules[f"{name}_ff"] = FFSynchronizer(pin, synced, init=1, stages=SYNC_STAGES)
        history = Signal(self.sampling.filter_samples - 1, init=-1, name=f"{name}_history")
        filtered = Signal(init=1, name=f"{name}_filtered")
        window = Cat(synced, history)
        m.d.sync += history.eq(window[: self.sampling.filter_samples - 1])
        with m.If(window.all()):
            m.d.sync += filtered.eq(1)
        with m.Elif(~window.any()):
            m.d.sync += filtered.eq(0)
        if not self.skippable:
            return filtered, Const(0)
        stages = Signal(SYNC_STAGES, init=-1, reset_less=True, name=f"{name}_stages")
        m.d.sync += stages.eq(Cat(pin, stages[:-1]))
        every = Cat(pin, stages, history, filtered)
        return filtered, every.all() | ~every.any()


class I2cTargetChecker(wiring.Component):
    """:class:`I2cTarget`'s protocol properties as ``Assert`` statements, on its signals.

    Why a component of its own: the engine binds it only with ``assertions`` on, and a
    test can drive it alone with a sequence no engine produces, to show each property
    fires. Every check runs on the ``sync`` clock.

    Attributes
    ----------
    scl : In(1)
        SCL as the engine sees it (synchronised and filtered).
    start_stop : In(1)
        A START or STOP is seen this cycle (the engine releases SDA at once).
    sda_drive, sda_oe : In(1)
        The engine's SDA pull-down before and after the ``mute`` fault.
    busy : In(1)
        The engine is addressed.
    drive_phase : In(1)
        The engine is in an address ACK, a write ACK or a read-data byte.
    hold_pending : In(1)
        An SDA change waits out the hold time after SCL fell.
    """

    scl: In(1)
    start_stop: In(1)
    sda_drive: In(1)
    sda_oe: In(1)
    busy: In(1)
    drive_phase: In(1)
    hold_pending: In(1)

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        drive_before = Signal()  # sda_drive one cycle back
        released = Signal()  # a START or STOP released SDA at the last edge
        m.d.sync += [drive_before.eq(self.sda_drive), released.eq(self.start_stop)]
        m.d.sync += [
            Assert(
                (self.sda_drive == drive_before) | ~self.scl | released,
                "I2C target changed SDA while SCL was high",
            ),
            Assert(~self.sda_oe | self.busy, "I2C target pulled SDA while not addressed"),
            Assert(
                ~self.sda_oe | self.drive_phase | self.hold_pending,
                "I2C target pulled SDA outside an ACK or read-data phase",
            ),
        ]
        return m
