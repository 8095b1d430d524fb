# amaranth: UnusedElaboratable=no
"""The target engines' protocol properties (``assertions=True``) under amaranth.sim.

Each property is shown to hold on the engine under legal traffic and to fire on an
illegal case: on the engine itself where the violation can be produced from outside
(traffic beyond the specification, a corrupted register, a mutant whose clock domain
``EnableInserter`` freezes), else on the engine's checker alone, driven with a sequence
no engine produces. A property that no test can make fire would prove nothing.
"""

from dataclasses import replace

import pytest
from amaranth.hdl import ClockDomain, EnableInserter, Module, Signal
from amaranth.sim import Simulator

from fpga_hdl.build import verilog_text
from fpga_hdl.buses.i2c_target import FAST_MODE, I2cTarget, I2cTargetChecker
from fpga_hdl.buses.spi_target import SpiTarget, SpiTargetChecker
from fpga_hdl.buses.transactions import I2cNack
from fpga_hdl.verification.amaranth_i2c import run_i2c_testbench
from fpga_hdl.verification.amaranth_spi import AmaranthSpiController, run_spi_testbench

SYS_CLK_HZ = 50e6
I2C_CLK_HZ = 10e6
ADDRESS = 0x0E
SENT = 0x5A  # the byte the SPI engine is given to send: differing bits, so a stuck SDO shows


def test_assertions_stay_out_of_the_product_verilog():
    """Off by default, and on they add checks to the netlist: the flag is what keeps them
    out of what Verilator, Icarus and synthesis see."""
    assert verilog_text(SpiTarget(), "t") != verilog_text(SpiTarget(assertions=True), "t")
    plain, checked = (
        I2cTarget(address=ADDRESS, sys_clk_hz=I2C_CLK_HZ),
        I2cTarget(address=ADDRESS, sys_clk_hz=I2C_CLK_HZ, assertions=True),
    )
    assert verilog_text(plain, "t") != verilog_text(checked, "t")
    assert not SpiTarget().assertions
    assert not plain.assertions


# --- SPI -----------------------------------------------------------------------------------


def spi_reads(dut, engine, *benches, mode=0, sclk_hz=1e6, flip=0) -> list[bytes]:
    """Three 4-byte transfers on ``engine``'s pins (``dut`` may be a mutant of it)."""
    out = []

    async def bench(ctx):
        ctx.set(engine.tx_data, SENT)
        ctx.set(engine.fault.flip, flip)
        spi = AmaranthSpiController(ctx, {"target": engine.spi}, mode=mode)
        await spi.idle()
        for _ in range(3):
            out.append(await spi.transfer("target", bytes(4), sclk_hz=sclk_hz))

    run_spi_testbench(dut, bench, *benches, sys_clk_hz=SYS_CLK_HZ)
    return out


@pytest.mark.parametrize("mode", [0, 3])
@pytest.mark.parametrize(("sclk_hz", "flip"), [(1e6, 0), (20e6, 0x81)])
def test_spi_properties_hold_on_legal_traffic(mode, sclk_hz, flip):
    engine = SpiTarget(assertions=True)
    reads = spi_reads(engine, engine, mode=mode, sclk_hz=sclk_hz, flip=flip)
    assert reads == [bytes([0, *[SENT ^ flip] * 3])] * 3  # the traffic really shifted data


def run_checker(checker, bench) -> None:
    """``bench(ctx)`` driving a checker alone, in the domains an engine would give it."""
    m = Module()
    m.submodules.checker = checker
    m.domains += [ClockDomain("spi_rx", local=True), ClockDomain("spi_tx", local=True)]
    sim = Simulator(m)
    sim.add_clock(1 / SYS_CLK_HZ)
    sim.add_testbench(bench)
    sim.run()


def test_sdo_driven_while_cs_high_fires():
    """SDO enabled with CS high: a bus contention no engine can produce, fed to the checker."""
    checker = SpiTargetChecker()

    async def bench(ctx):
        ctx.set(checker.cs_n, 0)
        ctx.set(checker.miso_oe, 1)
        await ctx.tick()
        await ctx.tick()  # selected and driving: fine
        ctx.set(checker.cs_n, 1)
        await ctx.tick()
        await ctx.tick()

    with pytest.raises(AssertionError, match=r"^Assertion violated: SPI target drives SDO while"):
        run_checker(checker, bench)


@pytest.mark.parametrize("mode", [0, 3])
def test_sdo_not_the_loaded_byte_fires(mode):
    """A mutant whose SDO shift register stops mid-byte (``spi_tx`` disabled)."""
    engine, shifting = SpiTarget(assertions=True), Signal(init=1)
    mutant = EnableInserter({"spi_tx": shifting})(engine)

    async def freeze(ctx):
        await ctx.negedge(engine.spi.cs_n)
        await ctx.delay(50e-9 + 11.5e-6)  # CS setup, the command byte, 3.5 data bits
        ctx.set(shifting, 0)

    with pytest.raises(AssertionError, match=r"SPI target's SDO is not the loaded byte's next bit"):
        spi_reads(mutant, engine, freeze, mode=mode)


# --- I2C -----------------------------------------------------------------------------------


def i2c_run(engine: I2cTarget, bench, *, timing=FAST_MODE):
    """``bench(ctx, controller)`` against the engine, which reads ``SENT`` at every byte."""

    async def with_data(ctx, controller):
        ctx.set(engine.read_data, SENT)
        return await bench(ctx, controller)

    return run_i2c_testbench(engine, engine.i2c, with_data, sys_clk_hz=I2C_CLK_HZ, timing=timing)


def test_i2c_properties_hold_on_legal_traffic():
    """Writes, reads with repeated START, a NACKed read, a foreign address and a STOP in
    between, in Fast-mode at the specification's minimum timings."""
    engine = I2cTarget(address=ADDRESS, sys_clk_hz=I2C_CLK_HZ, assertions=True)

    async def bench(ctx, i2c):
        out = [await i2c.write_read(ADDRESS, bytes([0x03, 0x70]), 0, scl_hz=400e3)]
        out.append(await i2c.write_read(ADDRESS, bytes([0x03]), 3, scl_hz=400e3))
        out.append(await i2c.write_read(ADDRESS, b"", 2, scl_hz=400e3))
        with pytest.raises(I2cNack):  # a foreign address: the target stays silent
            await i2c.write_read(0x0C, b"\x00", 1, scl_hz=400e3)
        return out

    assert i2c_run(engine, bench) == [b"", bytes([SENT] * 3), bytes([SENT] * 2)]


def test_sda_changing_while_scl_high_fires_on_a_too_short_scl_low():
    """A controller whose SCL low lasts 2 cycles (200 ns, t_LOW asks 1300 ns): the
    target's SDA comes after the next SCL rise."""
    engine = I2cTarget(address=ADDRESS, sys_clk_hz=I2C_CLK_HZ, assertions=True)

    async def bench(ctx, i2c):
        await i2c.write_read(ADDRESS, b"", 1, scl_hz=400e3)

    too_fast = replace(FAST_MODE, t_low_ns=200)
    with pytest.raises(AssertionError, match=r"I2C target changed SDA while SCL was high$"):
        i2c_run(engine, bench, timing=too_fast)


def test_sda_pulled_while_not_addressed_fires():
    """The ``busy`` register cleared (a bit flip) while the target ACKs its address."""
    engine = I2cTarget(address=ADDRESS, sys_clk_hz=I2C_CLK_HZ, assertions=True)

    async def bench(ctx, i2c):
        await i2c.start()
        for bit in range(7, -1, -1):
            await i2c.clock_bit((ADDRESS << 1) >> bit & 1)
        while not ctx.get(engine.i2c.sda_oe):  # the target's ACK
            await ctx.tick()
        ctx.set(engine.busy, 0)
        await ctx.tick()
        await ctx.tick()

    with pytest.raises(AssertionError, match=r"I2C target pulled SDA while not addressed$"):
        i2c_run(engine, bench)


def test_sda_pulled_outside_ack_or_read_data_fires():
    """SDA pulled by an addressed target in a write's data bits, no hold pending: a state
    no engine reaches, fed to the checker."""
    checker = I2cTargetChecker()

    async def bench(ctx):
        for name in ("busy", "sda_drive", "sda_oe", "drive_phase"):  # SCL low throughout
            ctx.set(getattr(checker, name), 1)
        await ctx.tick()
        await ctx.tick()  # an ACK: fine
        ctx.set(checker.drive_phase, 0)
        await ctx.tick()
        await ctx.tick()

    with pytest.raises(AssertionError, match=r"pulled SDA outside an ACK or read-data phase$"):
        run_checker(checker, bench)
