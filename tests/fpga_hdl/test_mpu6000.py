# amaranth: UnusedElaboratable=no
"""MPU-6000 core under amaranth.sim: register map, full scale, driver round trip, RTL = TLM."""

import asyncio

import numpy as np
import pytest

from fpga_hdl.buses.transactions import TlmSpiBus
from fpga_hdl.chips.mpu6000 import regs
from fpga_hdl.chips.mpu6000.core import Mpu6000
from fpga_hdl.chips.mpu6000.driver import Mpu6000Driver, decode
from fpga_hdl.chips.mpu6000.model import Mpu6000Model
from fpga_hdl.verification.amaranth_spi import AmaranthSpiController, run_spi_testbench
from fpga_hdl.verification.scoreboard import Scoreboard

SYS_CLK_HZ = 50e6


async def load(ctx, dut, sample: regs.Mpu6000Sample) -> None:
    ctx.set(dut.sample, sample.fields())
    ctx.set(dut.sample_stb, 1)
    await ctx.tick()
    ctx.set(dut.sample_stb, 0)
    await ctx.tick().repeat(4)


def run_on_rtl(script, *, mode: int = 0):
    """Run ``script(spi, ctx, dut)`` against the RTL; return what it returns."""
    dut = Mpu6000(sys_clk_hz=SYS_CLK_HZ)
    result = {}

    async def bench(ctx):
        spi = AmaranthSpiController(ctx, {"imu": dut.spi}, mode=mode)
        await spi.idle()
        await ctx.tick().repeat(3)
        result["value"] = await script(spi, ctx, dut)

    run_spi_testbench(dut, bench, sys_clk_hz=SYS_CLK_HZ)
    return result["value"]


def test_sys_clk_too_slow_for_20_mhz_sclk_is_refused():
    with pytest.raises(
        ValueError, match=r"^sys_clk_hz 5e\+06 is too slow for SCLK up to 2e\+07 Hz"
    ):
        Mpu6000(sys_clk_hz=5e6)


@pytest.mark.parametrize("mode", [0, 3])
def test_who_am_i_reset_values_and_read_only_writes(mode):
    async def script(spi, ctx, dut):
        drv = Mpu6000Driver(spi)
        before = [await drv.read_register(r) for r in (0x75, 0x6B, 0x1B, 0x1C)]
        await drv.write_register(0x75, 0x12)  # WHO_AM_I is read-only
        await drv.write_register(0x3B, 0x34)  # so are the data registers
        await drv.write_register(0x1B, 0x18)
        after = [await drv.read_register(r) for r in (0x75, 0x3B, 0x1B)]
        await drv.write_register(0x6B, 0x80)  # DEVICE_RESET
        reset = [await drv.read_register(r) for r in (0x6B, 0x1B)]
        return before, after, reset

    before, after, reset = run_on_rtl(script, mode=mode)
    assert before == [0x68, 0x40, 0x00, 0x00]  # RM-MPU-6000A-00 §3 reset values
    assert after == [0x68, 0x00, 0x18]
    assert reset == [0x40, 0x00]


FULL_SCALE_CASES = [
    # raw at finest resolution, selector, register value: raw >> sel, saturated to int16
    (16384, 0, 16384),
    (16384, 3, 2048),
    (40000, 0, 32767),  # above ±2 g: saturates at AFS_SEL 0 ...
    (40000, 1, 20000),  # ... fits at ±4 g
    (-40000, 0, -32768),
    (-3, 1, -2),  # arithmetic shift rounds toward -inf, like the model
    (262143, 3, 32767),
    (-262144, 3, -32768),
]


@pytest.mark.parametrize(("raw", "selector", "expected"), FULL_SCALE_CASES)
def test_full_scale_shift_and_saturation(raw, selector, expected):
    sample = regs.Mpu6000Sample(raw, 0, 0, 0, 0, 0, raw)

    async def script(spi, ctx, dut):
        drv = Mpu6000Driver(spi)
        await drv.write_register(0x6B, 0x01)  # wake up
        await drv.write_register(0x1C, selector << 3)
        await drv.write_register(0x1B, selector << 3)
        await load(ctx, dut, sample)
        return await drv.read_raw()

    data = run_on_rtl(script)
    assert int.from_bytes(data[0:2], "big", signed=True) == expected
    assert int.from_bytes(data[12:14], "big", signed=True) == expected
    assert regs.scaled_register_value(raw, selector) == expected


def test_sample_while_asleep_is_not_taken():
    async def script(spi, ctx, dut):
        drv = Mpu6000Driver(spi)
        await load(ctx, dut, regs.Mpu6000Sample(1000, 0, 0, 0, 0, 0, 0))
        asleep = await drv.read_raw()
        await drv.write_register(0x6B, 0x01)
        await ctx.tick().repeat(4)
        await load(ctx, dut, regs.Mpu6000Sample(1000, 0, 0, 0, 0, 0, 0))
        return asleep, await drv.read_raw()

    asleep, awake = run_on_rtl(script)
    assert asleep == bytes(14)
    assert awake[:2] == (1000).to_bytes(2, "big")


def test_driver_round_trip_through_rtl_equals_tlm_within_quantization():
    rng = np.random.default_rng(6000)
    samples = [
        (rng.uniform(-150, 150, 3), rng.uniform(-30, 30, 3), rng.uniform(-40, 85)) for _ in range(3)
    ]

    async def script(spi, ctx, dut):
        drv = Mpu6000Driver(spi)
        await drv.start()
        out = []
        for accel, gyro, temp in samples:
            await load(ctx, dut, regs.Mpu6000Sample.from_si(accel, gyro, temp))
            out.append(await drv.read_raw())
        return (drv.gyro_config, drv.accel_config), out

    (gyro_config, accel_config), rtl_bytes = run_on_rtl(script)
    assert (gyro_config, accel_config) == (0x18, 0x18)  # PX4: ±2000 °/s, ±16 g

    model = Mpu6000Model()
    tlm = Mpu6000Driver(TlmSpiBus({"imu": model}))
    asyncio.run(tlm.start())
    scoreboard = Scoreboard()
    for index, ((accel, gyro, temp), rtl) in enumerate(zip(samples, rtl_bytes, strict=True)):
        model.load_sample(regs.Mpu6000Sample.from_si(accel, gyro, temp))
        scoreboard.check(f"read_raw of sample {index}", asyncio.run(tlm.read_raw()), rtl)
        reading = decode(rtl, gyro_config, accel_config)
        # Loaded rounded at the finest LSB, then shifted (floored) to the ±16 g / ±2000 °/s
        # LSB: the error is under one register LSB plus half a load LSB.
        accel_tol = regs.accel_mps2_per_lsb(0x18) + regs.accel_mps2_per_lsb(0) / 2
        gyro_tol = regs.gyro_rads_per_lsb(0x18) + regs.gyro_rads_per_lsb(0) / 2
        np.testing.assert_allclose(reading.accel_mps2, accel, rtol=0, atol=accel_tol)
        np.testing.assert_allclose(reading.gyro_rads, gyro, rtol=0, atol=gyro_tol)
        assert reading.temperature_c == pytest.approx(temp, abs=0.5 / regs.TEMP_LSB_PER_C)


def test_sample_field_range_is_checked():
    with pytest.raises(
        ValueError, match=r"^MPU-6000 sample field gyro_z=524288 does not fit 20 bits$"
    ):
        regs.Mpu6000Sample(0, 0, 0, 0, 0, 0, 1 << 19)


def test_temperature_formula_datasheet():
    # RM-MPU-6000A-00 §4.18: °C = TEMP_OUT / 340 + 36.53; TEMP_OUT = 0 is 36.53 °C.
    reading = decode(bytes(6) + (-3400).to_bytes(2, "big", signed=True) + bytes(6), 0, 0)
    assert reading.temperature_c == pytest.approx(26.53, abs=1e-12)
