"""SPI engine under amaranth.sim: abort mid-byte, back-to-back, coherence against updates."""

import numpy as np
import pytest

from fpga_hdl.buses.spi_target import check_sys_clk_for_spi
from fpga_hdl.chips.mpu6000 import regs
from fpga_hdl.chips.mpu6000.core import Mpu6000
from fpga_hdl.verification.amaranth_spi import AmaranthSpiController, run_spi_testbench

SYS_CLK_HZ = 50e6


def test_sys_clk_limit_is_exact():
    check_sys_clk_for_spi(8.01e6, 20e6)  # 3 cycles = 374.5 ns < 375 ns
    with pytest.raises(ValueError, match=r"use more than 8e\+06 Hz$"):
        check_sys_clk_for_spi(8e6, 20e6)


@pytest.mark.parametrize("mode", [0, 3])
@pytest.mark.parametrize("abort_after_bits", [1, 4, 7, 12])
def test_transfer_aborted_mid_byte_leaves_the_core_ready(mode, abort_after_bits):
    dut = Mpu6000(sys_clk_hz=SYS_CLK_HZ)
    result = {}

    async def bench(ctx):
        spi = AmaranthSpiController(ctx, {"imu": dut.spi}, mode=mode)
        await spi.idle()
        # A write of 0xFF to GYRO_CONFIG, cut after some bits by CS rising.
        ctx.set(dut.spi.cs_n, 0)
        await ctx.delay(50e-9)
        bits = [int(b) for b in f"{0x1B:08b}{0xFF:08b}"][:abort_after_bits]
        for bit in bits:
            ctx.set(dut.spi.sclk, 0)
            ctx.set(dut.spi.mosi, bit)
            await ctx.delay(25e-9)
            ctx.set(dut.spi.sclk, 1)
            await ctx.delay(25e-9)
        ctx.set(dut.spi.cs_n, 1)
        ctx.set(dut.spi.sclk, 1 if mode == 3 else 0)
        await ctx.delay(100e-9)
        result["who"] = await spi.transfer("imu", bytes([0xF5, 0]), sclk_hz=1e6)
        result["gyro_config"] = await spi.transfer("imu", bytes([0x9B, 0]), sclk_hz=1e6)

    run_spi_testbench(dut, bench, sys_clk_hz=SYS_CLK_HZ)
    assert result["who"] == bytes([0x00, 0x68])
    assert result["gyro_config"] == bytes([0x00, 0x00])  # the cut write never landed


@pytest.mark.parametrize("mode", [0, 3])
def test_back_to_back_transfers_at_20_mhz(mode):
    dut = Mpu6000(sys_clk_hz=SYS_CLK_HZ)
    out = []

    async def bench(ctx):
        spi = AmaranthSpiController(ctx, {"imu": dut.spi}, mode=mode, cs_setup_s=8e-9, cs_hold_s=0)
        await spi.idle()
        for _ in range(3):
            out.append(await spi.transfer("imu", bytes([0xF5, 0, 0]), sclk_hz=20e6))

    run_spi_testbench(dut, bench, sys_clk_hz=SYS_CLK_HZ)
    # WHO_AM_I then auto-increment past the map's end (0x76 is unimplemented: 0x00).
    assert out == [bytes([0x00, 0x68, 0x00])] * 3


def test_read_racing_an_update_is_never_mixed():
    """Randomised, seeded: a sample offered at any moment during a burst never tears it."""
    rng = np.random.default_rng(3)
    old = regs.Mpu6000Sample(*(int(v) for v in rng.integers(-30000, 30000, 7)))
    new = regs.Mpu6000Sample(*(int(v) for v in rng.integers(-30000, 30000, 7)))
    old_bytes = regs.data_register_bytes(old, 0, 0)
    new_bytes = regs.data_register_bytes(new, 0, 0)
    burst_s = 15 * 8 / 20e6
    # Half the offsets around CS falling (the race window), half across the burst.
    offsets_s = np.concatenate([rng.uniform(-0.6e-6, 0.3e-6, 8), rng.uniform(0, burst_s, 6)])
    seen = set()
    for offset_s in offsets_s:
        dut = Mpu6000(sys_clk_hz=SYS_CLK_HZ)
        rx = {}

        async def reader(ctx, dut=dut, rx=rx):
            spi = AmaranthSpiController(ctx, {"imu": dut.spi}, mode=0, cs_setup_s=8e-9)
            await spi.idle()
            await spi.transfer("imu", bytes([0x6B, 0x01]), sclk_hz=1e6)  # wake up
            ctx.set(dut.sample, old.fields())
            ctx.set(dut.sample_stb, 1)
            await ctx.tick()
            ctx.set(dut.sample_stb, 0)
            await ctx.tick().repeat(5)
            rx["data"] = (await spi.transfer("imu", bytes([0xBB]) + bytes(14), sclk_hz=20e6))[1:]

        async def host(ctx, dut=dut, offset_s=offset_s):
            await ctx.posedge(dut.spi.cs_n)  # end of the wake-up write
            # The burst starts half a 1 MHz period plus six system cycles later.
            await ctx.delay(0.5e-6 + 6 * 20e-9 + offset_s)
            await ctx.tick()
            ctx.set(dut.sample, new.fields())
            ctx.set(dut.sample_stb, 1)
            await ctx.tick()
            ctx.set(dut.sample_stb, 0)

        run_spi_testbench(dut, reader, host, sys_clk_hz=SYS_CLK_HZ)
        assert rx["data"] in (old_bytes, new_bytes), f"mixed sample at offset {offset_s:.3e} s"
        seen.add(rx["data"])
    assert seen == {old_bytes, new_bytes}  # the offsets really straddle the burst
