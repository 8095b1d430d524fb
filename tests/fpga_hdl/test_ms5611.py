"""MS5611: datasheet arithmetic, AN520 CRC4, inverse compensation, RTL = TLM, timing of ADC."""

import asyncio

import pytest

from fpga_hdl.buses.transactions import TlmSpiBus
from fpga_hdl.chips.ms5611 import regs
from fpga_hdl.chips.ms5611.core import Ms5611
from fpga_hdl.chips.ms5611.driver import Ms5611Driver, Ms5611Error
from fpga_hdl.chips.ms5611.model import Ms5611Model, raw_from_si
from fpga_hdl.verification.amaranth_spi import AmaranthSpiController, run_spi_testbench
from fpga_hdl.verification.scoreboard import Scoreboard

SYS_CLK_HZ = 50e6


def test_datasheet_worked_example():
    # MS5611-01BA03 "Pressure and temperature calculation": typical values column.
    result = regs.compensate(9085466, 8569150, regs.DEFAULT_PROM)
    assert (result.dt, result.temp, result.off, result.sens, result.pressure) == (
        2366,
        2007,
        2420281617,
        1315097036,
        100009,
    )


def test_an520_crc4_example_and_default_prom():
    # AN520's example PROM 0x3132..0x4500 has CRC 0xB.
    example = (0x3132, 0x3334, 0x3536, 0x3738, 0x3940, 0x4142, 0x4344, 0x4500)
    assert regs.crc4(example) == 0xB
    assert regs.DEFAULT_PROM[1:7] == regs.DATASHEET_COEFFICIENTS
    assert regs.crc4(regs.DEFAULT_PROM) == regs.DEFAULT_PROM[7] & 0xF


def test_second_order_compensation_closed_form():
    prom = regs.DEFAULT_PROM
    c1, c2, c3, c4, c5, c6 = prom[1:7]
    d1, d2 = 8_000_000, 7_300_000  # well below 20 °C and below -15 °C
    dt = d2 - c5 * 256
    temp = 2000 + dt * c6 // 2**23
    assert temp < -1500
    off2 = 5 * (temp - 2000) ** 2 // 2 + 7 * (temp + 1500) ** 2
    sens2 = 5 * (temp - 2000) ** 2 // 4 + 11 * (temp + 1500) ** 2 // 2
    off = c2 * 2**16 + c4 * dt // 2**7 - off2
    sens = c1 * 2**15 + c3 * dt // 2**8 - sens2
    result = regs.compensate(d1, d2, prom)
    assert result.temp == temp - dt * dt // 2**31
    assert result.pressure == (d1 * sens // 2**21 - off) // 2**15


@pytest.mark.parametrize(
    ("pressure_pa", "temperature_c"),
    [(101325, 15.0), (100009, 20.07), (1000, 85.0), (120000, -40.0), (54000, -20.0), (80000, 5.5)],
)
def test_inverse_compensation_round_trip(pressure_pa, temperature_c):
    d1, d2 = raw_from_si(pressure_pa, temperature_c)
    result = regs.compensate(d1, d2, regs.DEFAULT_PROM)
    assert result.pressure == pressure_pa  # 1 Pa = 0.01 mbar, the output resolution
    assert result.temp == round(temperature_c * 100)


def test_inverse_out_of_range_is_a_clear_error():
    with pytest.raises(
        ValueError, match=r"^MS5611 pressure \(Pa\) 900000 is outside what a 24-bit"
    ):
        raw_from_si(900000, 20.0)


def run_on_rtl(script, *, mode=3, prom=regs.DEFAULT_PROM):
    dut = Ms5611(sys_clk_hz=SYS_CLK_HZ, prom=prom)
    result = {}

    async def bench(ctx):
        spi = AmaranthSpiController(ctx, {"baro": dut.spi}, mode=mode)
        await spi.idle()

        async def sleep_us(us):
            ctx.set(dut.now_us, ctx.get(dut.now_us) + us)
            await ctx.tick().repeat(4)

        result["value"] = await script(spi, ctx, dut, sleep_us)

    run_spi_testbench(dut, bench, sys_clk_hz=SYS_CLK_HZ)
    return result["value"]


@pytest.mark.parametrize("osr", list(regs.Osr))
def test_adc_read_is_zero_until_the_conversion_time_has_passed(osr):
    async def script(spi, ctx, dut, sleep_us):
        ctx.set(dut.sample, {"d1": 0x123456, "d2": 0x654321})
        ctx.set(dut.sample_stb, 1)
        await ctx.tick()
        ctx.set(dut.sample_stb, 0)
        drv = Ms5611Driver(spi, sleep_us, osr=osr)
        wait_us = regs.CONVERSION_TIME_US[osr]
        await drv.convert(regs.CMD_CONVERT_D1)
        await sleep_us(wait_us - 1)
        early = await drv.read_adc()
        await drv.convert(regs.CMD_CONVERT_D2)
        await sleep_us(wait_us)
        on_time = await drv.read_adc()
        repeated = await drv.read_adc()
        return early, on_time, repeated

    assert run_on_rtl(script) == (0, 0x654321, 0)


def test_driver_round_trip_rtl_equals_tlm():
    pressure_pa, temperature_c = 97_500, -18.25  # second-order branch
    d1, d2 = raw_from_si(pressure_pa, temperature_c)

    async def script(spi, ctx, dut, sleep_us):
        ctx.set(dut.sample, {"d1": d1, "d2": d2})
        ctx.set(dut.sample_stb, 1)
        await ctx.tick()
        ctx.set(dut.sample_stb, 0)
        drv = Ms5611Driver(spi, sleep_us)
        await drv.start()
        return drv.prom, await drv.measure()

    prom, rtl = run_on_rtl(script, mode=0)
    assert prom == regs.DEFAULT_PROM
    assert (rtl.pressure_pa, rtl.temperature_c) == (pressure_pa, temperature_c)

    model = Ms5611Model()
    model.load_sample(d1, d2)

    async def sleep_us(us):
        model.now_us += us

    tlm = Ms5611Driver(TlmSpiBus({"baro": model}), sleep_us)
    asyncio.run(tlm.start())
    Scoreboard().check("PX4 measure()", asyncio.run(tlm.measure()), rtl)


def test_driver_rejects_a_bad_crc():
    bad = (*regs.DEFAULT_PROM[:7], regs.DEFAULT_PROM[7] ^ 0x1)

    async def script(spi, ctx, dut, sleep_us):
        with pytest.raises(
            Ms5611Error, match=r"^MS5611 PROM CRC4 mismatch: computed 0x8, word 7 holds 0x9$"
        ):
            await Ms5611Driver(spi, sleep_us).start()
        return True

    assert run_on_rtl(script, prom=bad)


def test_model_transfer_matches_rtl_for_every_command():
    commands = [bytes([0xA0 + 2 * i, 0, 0]) for i in range(8)]
    commands += [bytes([0x48]), bytes([0x00, 0, 0, 0]), bytes([0x1E]), bytes([0x00, 0, 0, 0])]
    commands += [bytes([0x33, 0, 0]), bytes([0xA1, 0, 0])]  # unknown and odd PROM address

    async def script(spi, ctx, dut, sleep_us):
        ctx.set(dut.sample, {"d1": 0xABCDEF, "d2": 1})
        ctx.set(dut.sample_stb, 1)
        await ctx.tick()
        ctx.set(dut.sample_stb, 0)
        out = []
        for tx in commands:
            out.append(await spi.transfer("baro", tx, sclk_hz=20e6))
            await sleep_us(10_000)
        return out

    rtl = run_on_rtl(script)
    model = Ms5611Model()
    model.load_sample(0xABCDEF, 1)
    scoreboard = Scoreboard()
    for tx, observed in zip(commands, rtl, strict=True):
        scoreboard.check(f"spi baro {tx.hex()}", model.transfer(tx), observed)
        model.now_us += 10_000
    assert rtl[9] == bytes([0, 0xAB, 0xCD, 0xEF])
