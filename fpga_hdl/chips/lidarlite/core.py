"""LIDAR-Lite v3 rangefinder emulated on I2C (Garmin's manual; register map in regs.py)."""

from amaranth.build import Platform
from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring

from fpga_hdl.buses.i2c_target import (
    I2cTarget,
    TargetSampling,
    i2c_chip_members,
    settle_i2c_chip,
)
from fpga_hdl.chips.lidarlite import regs
from fpga_hdl.chips.lidarlite.regs import Register
from fpga_hdl.host.host_port import chip_sample_latch

__all__ = ["LidarLiteCore"]


class LidarLiteCore(wiring.Component):
    """LIDAR-Lite v3 register file behind an :class:`~fpga_hdl.buses.i2c_target.I2cTarget`.

    Behaviour emulated: writing ACQ_COMMAND = 0x03/0x04 measures the visible sample; the
    result (FULL_DELAY_HIGH/LOW, SIGNAL_STRENGTH, PEAK_CORR) becomes readable
    ``regs.ACQUISITION_TIME_US`` later in simulated time (``now_us``), so no clock has to
    run while the bus is idle; until then the previous result reads and STATUS.BUSY is 1.
    ACQ_COMMAND = 0x00 restores the configuration registers' reset values. STATUS also
    reports health (always) and an invalid signal when the standing result is a no return.
    The first byte written after a START is the register pointer, whose bit 7 asks for
    auto-increment (without it successive bytes stay on one register); a wrong address
    is NACKed. The TLM twin is :class:`~fpga_hdl.chips.lidarlite.model.LidarLiteModel`.

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the ``sync`` domain (see :class:`I2cTarget` for the choice).
    address : int
        7-bit address (0x62 from the factory).

    Attributes
    ----------
    i2c : In(I2C)
        The I2C bus (SDA resolved by the top or testbench; ``sda_oe`` = 1 pulls it low).
    sample : In(regs.SAMPLE_LAYOUT)
        The scene the next acquisition measures. Must hold from ``sample_stb`` until the
        next one (the host port's staging register).
    sample_stb : In(1)
        One-cycle strobe: a new ``sample`` is offered; it becomes visible once no
        transaction with this chip runs.
    sample_pending : Out(1)
        An offered sample waits for the running transaction's STOP.
    now_us : In(32)
        Simulated time in microseconds, written by the host; wraps modulo 2**32.
    fault : In(BUS_FAULT)
        While ``mute`` is 1 the chip does not answer (no ACK); ``flip`` is XORed into
        every byte the chip sends.
    settled : Out(1)
        ``skippable`` only: nothing changes at the coming edges until the bus does
        (:func:`~fpga_hdl.buses.i2c_target.settle_i2c_chip`).
    """

    def __init__(self, *, sys_clk_hz: float, address: int = regs.DEFAULT_ADDRESS,
                 skippable: bool = False) -> None:  # fmt: skip
        self.address = address
        self.sampling = TargetSampling.for_clock(sys_clk_hz)
        self.skippable = skippable
        super().__init__(i2c_chip_members(regs.SAMPLE_LAYOUT, skippable=skippable))

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        m.submodules.target = target = I2cTarget(
            address=self.address, sys_clk_hz=self.sampling.sys_clk_hz, skippable=self.skippable
        )
        wiring.connect(m, wiring.flipped(self.i2c), target.i2c)
        wiring.connect(m, wiring.flipped(self.fault), target.fault)

        latch = chip_sample_latch(m, self, regs.SAMPLE_LAYOUT, busy=target.busy)
        if self.skippable:
            settle_i2c_chip(m, self, target, latch)

        stored = {
            reg: Signal(8, init=init, name=reg.name.lower())
            for reg, init in regs.STORED_REGISTERS.items()
        }
        measured = Signal(regs.SAMPLE_LAYOUT)  # the running (or finished) acquisition
        previous = Signal(regs.SAMPLE_LAYOUT)  # what reads while an acquisition runs
        measuring = Signal()
        started_us = Signal(32)
        finished = measuring & ((self.now_us - started_us)[:32] >= regs.ACQUISITION_TIME_US)
        shown = Signal(regs.SAMPLE_LAYOUT)
        m.d.comb += shown.eq(Mux(finished, measured, previous))

        pointer = Signal(8)
        register = pointer & regs.POINTER_REGISTER_MASK
        results = {
            Register.PEAK_CORR: shown.peak_strength,
            Register.SIGNAL_STRENGTH: shown.signal_strength,
            Register.FULL_DELAY_HIGH: shown.distance_cm[8:],
            Register.FULL_DELAY_LOW: shown.distance_cm[:8],
        }
        status = (
            regs.STATUS_HEALTH
            | Mux(measuring & ~finished, regs.STATUS_BUSY, 0)
            | Mux(shown.signal_strength == 0, regs.STATUS_INVALID_SIGNAL, 0)
        )
        with m.Switch(register):
            with m.Case(Register.STATUS):
                m.d.comb += target.read_data.eq(status)
            for reg, value in results.items():
                with m.Case(reg):
                    m.d.comb += target.read_data.eq(value)
            for reg, value in stored.items():
                with m.Case(reg):
                    m.d.comb += target.read_data.eq(value)
            for reg, value in regs.ID_REGISTERS.items():
                with m.Case(reg):
                    m.d.comb += target.read_data.eq(value)
            with m.Default():
                m.d.comb += target.read_data.eq(0)

        # Every byte makes a finished acquisition's result the standing one (the model's
        # ``_settle``), so a later wrap of ``now_us`` cannot hide it.
        with m.If((target.write_stb | target.read_stb) & finished):
            m.d.sync += [previous.eq(measured), measuring.eq(0)]

        # Auto-increment stays within the 7-bit register space (regs.next_pointer).
        advanced = Mux(
            pointer & regs.POINTER_AUTO_INCREMENT,
            regs.POINTER_AUTO_INCREMENT | (pointer + 1)[:7],
            pointer,
        )
        pointer_next = Signal()
        with m.If(target.start):
            m.d.sync += pointer_next.eq(1)
        with m.Elif(target.write_stb & pointer_next):
            m.d.sync += [pointer.eq(target.write_data), pointer_next.eq(0)]
        with m.Elif(target.write_stb):
            m.d.sync += pointer.eq(advanced)
            byte = target.write_data
            with m.Switch(register):
                with m.Case(Register.ACQ_COMMAND):
                    with m.If((byte == regs.ACQ_MEASURE) | (byte == regs.ACQ_MEASURE_NO_BIAS)):
                        m.d.sync += [
                            previous.eq(shown),
                            measured.eq(latch.visible),
                            measuring.eq(1),
                            started_us.eq(self.now_us),
                        ]
                    with m.Elif(byte == regs.ACQ_RESET):
                        m.d.sync += measuring.eq(0)
                        m.d.sync += [r.eq(regs.STORED_REGISTERS[reg]) for reg, r in stored.items()]
                for reg, value in stored.items():
                    with m.Case(reg):
                        m.d.sync += value.eq(byte)
        with m.Elif(target.read_stb):
            m.d.sync += pointer.eq(advanced)
        return m
