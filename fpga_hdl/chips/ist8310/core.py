"""IST8310 magnetometer emulated on I2C (iSentek IST8310 datasheet; register map in regs.py)."""

from amaranth.build import Platform
from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring

from fpga_hdl.buses.i2c_target import (
    I2cTarget,
    TargetSampling,
    i2c_chip_members,
    settle_i2c_chip,
)
from fpga_hdl.chips.ist8310 import regs
from fpga_hdl.chips.ist8310.regs import Register
from fpga_hdl.host.host_port import chip_sample_latch

__all__ = ["Ist8310Core"]


class Ist8310Core(wiring.Component):
    """IST8310 register file behind an :class:`~fpga_hdl.buses.i2c_target.I2cTarget`.

    Behaviour emulated: WAI reads 0x10; writing CNTL1 = single measurement starts a
    measurement that completes ``regs.MEASUREMENT_TIME_US`` later in simulated time
    (``now_us``), so no clock has to run while the bus is idle; STAT1.DRDY is then 1 and
    CNTL1 reads back standby; reading any data register clears DRDY; data registers
    are little-endian int16 at 1320 LSB/G (CNTL3 16-bit bits set) or 330 LSB/G (14-bit,
    the power-on default); CNTL2.SRST resets every register; reads and writes
    auto-increment the register pointer (0xFF wraps to 0x00); a wrong address is NACKed.

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the ``sync`` domain (see :class:`I2cTarget` for the choice).
    address : int
        7-bit address, one of ``regs.ADDRESSES`` (the CAD pins' choices).

    Attributes
    ----------
    i2c : In(I2C)
        The I2C bus (SDA resolved by the top or testbench; ``sda_oe`` = 1 pulls it low).
    sample : In(regs.SAMPLE_LAYOUT)
        Field in 16-bit-mode counts, chip axes. Must hold from ``sample_stb`` until the
        next one (the host port's staging register).
    sample_stb : In(1)
        One-cycle strobe: a new ``sample`` is offered. It becomes visible at once when no
        transaction with this chip is running, else at the transaction's STOP, so one
        read never mixes two samples.
    sample_pending : Out(1)
        An offered sample waits for the running transaction's STOP (a simulation that
        gates the system clock keeps it running while this is 1).
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
        regs.check_address(address)
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

        # Double buffer: the visible sample changes only between transactions.
        latch = chip_sample_latch(m, self, regs.SAMPLE_LAYOUT, busy=target.busy)
        if self.skippable:
            settle_i2c_chip(m, self, target, latch)
        visible = latch.visible

        stored = {reg: Signal(8, name=reg.name.lower()) for reg in regs.STORED_REGISTERS}
        cntl3 = stored[Register.CNTL3]
        measuring = Signal()
        started_us = Signal(32)
        finished = measuring & ((self.now_us - started_us)[:32] >= regs.MEASUREMENT_TIME_US)

        # Output resolution per axis: 16-bit counts, or 14-bit (shifted right) by default.
        out = {}
        for name, bit in (
            ("x", regs.CNTL3_X_16BIT),
            ("y", regs.CNTL3_Y_16BIT),
            ("z", regs.CNTL3_Z_16BIT),
        ):
            counts = visible[name]
            out[name] = Signal.like(counts, name=f"data_{name}")
            m.d.comb += out[name].eq(Mux(cntl3 & bit, counts, counts >> regs.SHIFT_14BIT))

        pointer = Signal(8)
        with m.Switch(pointer):
            with m.Case(Register.WAI):
                m.d.comb += target.read_data.eq(regs.DEVICE_ID)
            with m.Case(Register.STAT1):
                m.d.comb += target.read_data.eq(Mux(finished, regs.STAT1_DRDY, 0))
            for index, reg in enumerate(regs.DATA_REGISTERS):
                with m.Case(reg):
                    value = out["xyz"[index // 2]]
                    m.d.comb += target.read_data.eq(value.as_unsigned().word_select(index % 2, 8))
            with m.Case(Register.CNTL1):
                mode = Mux(measuring & ~finished, regs.CNTL1_MODE_SINGLE, 0)
                m.d.comb += target.read_data.eq(mode)
            for reg, register in stored.items():
                with m.Case(reg):
                    m.d.comb += target.read_data.eq(register)
            with m.Default():
                m.d.comb += target.read_data.eq(0)

        # The first byte written after a START is the register pointer (datasheet I2C
        # write sequence); later bytes write registers with auto-increment.
        pointer_next = Signal()
        with m.If(target.start):
            m.d.sync += pointer_next.eq(1)
        with m.Elif(target.write_stb & pointer_next):
            m.d.sync += [pointer.eq(target.write_data), pointer_next.eq(0)]
        with m.Elif(target.write_stb):
            m.d.sync += pointer.eq(pointer + 1)
            byte = target.write_data
            with m.Switch(pointer):
                with m.Case(Register.CNTL1):
                    is_single = (byte & regs.CNTL1_MODE_MASK) == regs.CNTL1_MODE_SINGLE
                    m.d.sync += [measuring.eq(is_single), started_us.eq(self.now_us)]
                with m.Case(Register.CNTL2):
                    with m.If(byte & regs.CNTL2_SRST):
                        m.d.sync += [measuring.eq(0), *(r.eq(0) for r in stored.values())]
                    with m.Else():
                        m.d.sync += stored[Register.CNTL2].eq(
                            byte & regs.STORED_REGISTERS[Register.CNTL2]
                        )
                for reg, mask in regs.STORED_REGISTERS.items():
                    if reg != Register.CNTL2:
                        with m.Case(reg):
                            m.d.sync += stored[reg].eq(byte & mask)
        with m.Elif(target.read_stb):
            m.d.sync += pointer.eq(pointer + 1)
            reads_data = (pointer >= Register.DATAXL) & (pointer <= Register.DATAZH)
            with m.If(reads_data & finished):
                m.d.sync += measuring.eq(0)
        return m
