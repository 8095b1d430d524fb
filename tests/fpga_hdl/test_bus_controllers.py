# amaranth: UnusedElaboratable=no
"""amaranth.sim tests of the autopilot-side peripherals: SPI and I2C controllers and the
PWM generator (the PWM results' synchroniser: ``test_snapshot_cdc.py``)."""

import math
import re

import numpy as np
import pytest
from amaranth.hdl import Module, Signal
from amaranth.sim import Simulator

from fpga_hdl.buses.i2c_controller import I2cBitCycles, I2cController, controller_rate_hz
from fpga_hdl.buses.i2c_target import FAST_MODE, STANDARD_MODE
from fpga_hdl.buses.pwm_generator import PwmGenerator
from fpga_hdl.buses.spi_controller import SpiController, SpiControllerTiming, divider_for
from fpga_hdl.chips.ist8310.core import Ist8310Core

SYS_CLK_HZ = 10e6


def run(m, bench, *, clk_hz=SYS_CLK_HZ):
    sim = Simulator(m)
    sim.add_clock(1 / clk_hz)
    result = {}

    async def testbench(ctx):
        result["value"] = await bench(ctx)

    sim.add_testbench(testbench)
    sim.run()
    return result["value"]


async def request(ctx, dut) -> int:
    """Flip the request toggle; return the cycles until the acknowledge follows."""
    ctx.set(dut.request, 1 - ctx.get(dut.request))
    cycles = 0
    while ctx.get(dut.acknowledge) != ctx.get(dut.request):
        await ctx.tick()
        cycles += 1
    return cycles


@pytest.mark.parametrize(
    ("sys_clk_hz", "sclk_hz", "divider"),
    [(10e6, 5e6, 1), (10e6, 20e6, 1), (10e6, 1e6, 5), (16e6, 5e6, 2), (16e6, 1e6, 8)],
)
def test_divider_never_exceeds_the_requested_sclk(sys_clk_hz, sclk_hz, divider):
    assert divider_for(sys_clk_hz, sclk_hz) == divider
    assert sys_clk_hz / (2 * divider) <= max(sclk_hz, sys_clk_hz / 2)


def test_divider_rejects_an_unreachable_rate():
    with pytest.raises(ValueError, match=r"^sclk_hz 10000 is below the slowest SCLK"):
        divider_for(10e6, 10e3)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"devices": 0}, "devices must be a positive integer, not 0"),
        ({"devices": 2, "depth": 0}, "depth must be a positive integer, not 0"),
        ({"devices": 2, "sys_clk_hz": -1.0}, "sys_clk_hz must be a positive frequency in Hz"),
    ],
)
def test_spi_controller_rejects_bad_parameters(kwargs, message):
    with pytest.raises(ValueError, match="^" + message):
        SpiController(**{"sys_clk_hz": SYS_CLK_HZ, **kwargs})


def test_spi_timing_rejects_negative_durations():
    with pytest.raises(ValueError, match=r"^cs_hold_s must be a finite duration >= 0 s, not -1"):
        SpiControllerTiming(cs_hold_s=-1)


@pytest.mark.parametrize("mode3", [0, 1])
@pytest.mark.parametrize(("length", "divider"), [(1, 1), (2, 5), (15, 1), (32, 2)])
def test_spi_controller_loopback_returns_every_byte_in_order(mode3, length, divider):
    """MISO wired to MOSI: the controller must read back exactly what it sent, so bytes
    and bits go out and come in in the same order, for every length and divider."""
    ctrl = SpiController(sys_clk_hz=SYS_CLK_HZ, devices=2)
    m = Module()
    m.submodules.ctrl = ctrl
    m.d.comb += ctrl.miso.eq(ctrl.mosi)
    tx = bytes(np.random.default_rng(length).integers(0, 256, length, dtype=np.uint8))

    async def bench(ctx):
        ctx.set(ctrl.mode3, mode3)
        ctx.set(ctrl.divider, divider)
        ctx.set(ctrl.length, length)
        ctx.set(ctrl.device, 1)
        ctx.set(ctrl.tx, int.from_bytes(tx, "little"))
        cycles = await request(ctx, ctrl)
        rx = ctx.get(ctrl.rx).to_bytes(ctrl.depth, "little")[:length]
        return cycles, rx, ctx.get(ctrl.cs_n), ctx.get(ctrl.sclk)

    cycles, rx, cs_n, sclk = run(m, bench)
    assert rx == tx
    assert cycles == ctrl.transfer_cycles(length, divider)
    assert (cs_n, sclk) == (0b11, mode3)  # released, SCLK back at its idle level


@pytest.mark.parametrize(("scl_hz", "spec"), [(100e3, STANDARD_MODE), (400e3, FAST_MODE)])
@pytest.mark.parametrize("sys_clk_hz", [10e6, 16e6])
def test_i2c_bit_cycles_cover_um10204_and_never_exceed_the_rate(scl_hz, spec, sys_clk_hz):
    cycles = I2cBitCycles.for_rate(scl_hz, sys_clk_hz)
    ns = 1e9 / sys_clk_hz
    for field, minimum in (
        ("low", spec.t_low_ns),
        ("high", spec.t_high_ns),
        ("hd_sta", spec.t_hd_sta_ns),
        ("su_sta", spec.t_su_sta_ns),
        ("su_sto", spec.t_su_sto_ns),
        ("buf", spec.t_buf_ns),
    ):
        assert getattr(cycles, field) * ns >= minimum, field
    assert (cycles.low - cycles.hd_dat) * ns >= spec.t_su_dat_ns
    assert sys_clk_hz / cycles.bit <= scl_hz
    assert sys_clk_hz / cycles.bit > 0.95 * scl_hz  # and not needlessly slow


def test_i2c_bit_cycles_at_10_mhz_match_hand_count():
    # 400 kHz: t_LOW 1300 + 300 = 1600 ns, t_HIGH 600 + 300 = 900 ns (slack split evenly).
    assert (I2cBitCycles.for_rate(400e3, 10e6).low, I2cBitCycles.for_rate(400e3, 10e6).high) == (
        16,
        9,
    )


@pytest.mark.parametrize(
    ("scl_hz", "rate_hz"), [(400e3, 400e3), (1e6 / 3, 100e3), (100e3, 100e3), (399e3, 100e3)]
)
def test_controller_rate_rounds_down(scl_hz, rate_hz):
    assert controller_rate_hz(scl_hz) == rate_hz


@pytest.mark.parametrize(
    ("scl_hz", "message"),
    [
        (1e6, "scl_hz 1e+06 is above Fast-mode (400 kHz), the controller's top"),
        (50e3, "scl_hz 50000 is below the controller's slowest rate, 100 kHz"),
        (math.nan, "scl_hz must be a positive finite frequency in Hz, not nan"),
    ],
)
def test_controller_rate_rejects_what_it_cannot_run(scl_hz, message):
    with pytest.raises(ValueError, match="^" + re.escape(message)):
        controller_rate_hz(scl_hz)


def i2c_on_ist8310():
    ctrl, chip = I2cController(sys_clk_hz=SYS_CLK_HZ), Ist8310Core(sys_clk_hz=SYS_CLK_HZ)
    m = Module()
    m.submodules.ctrl, m.submodules.chip = ctrl, chip
    sda = Signal()
    m.d.comb += [
        sda.eq(ctrl.sda_o & ~chip.i2c.sda_oe),
        chip.i2c.scl.eq(ctrl.scl),
        chip.i2c.sda_i.eq(sda),
        ctrl.sda_i.eq(sda),
    ]
    return m, ctrl


async def i2c_transfer(ctx, ctrl, address, write: bytes, read_len: int, fast=1):
    ctx.set(ctrl.address, address)
    ctx.set(ctrl.write_len, len(write))
    ctx.set(ctrl.read_len, read_len)
    ctx.set(ctrl.tx, int.from_bytes(write, "little"))
    ctx.set(ctrl.fast, fast)
    cycles = await request(ctx, ctrl)
    rx = ctx.get(ctrl.rx).to_bytes(ctrl.read_depth, "little")[:read_len]
    return cycles, rx, ctx.get(ctrl.nack), ctx.get(ctrl.nack_index)


def test_i2c_controller_reads_writes_and_reports_nacks_on_the_ist8310():
    m, ctrl = i2c_on_ist8310()

    async def bench(ctx):
        await ctx.tick().repeat(4)
        who = await i2c_transfer(ctx, ctrl, 0x0E, b"\x00", 1)
        write = await i2c_transfer(ctx, ctrl, 0x0E, b"\x0d\x70", 0)  # CNTL3 = 16-bit
        back = await i2c_transfer(ctx, ctrl, 0x0E, b"\x0d", 1, fast=0)
        absent = await i2c_transfer(ctx, ctrl, 0x0F, b"\x00", 1)
        refused = await i2c_transfer(ctx, ctrl, 0x0E, b"\x00\x01\x02", 0)  # WAI is read-only
        return who, write, back, absent, refused

    who, write, back, absent, refused = run(m, bench)
    assert who[1:] == (b"\x10", 0, 0)
    assert write[2] == 0
    assert back[1:] == (b"\x70", 0, 0)
    assert absent[2:] == (1, 0)
    # By hand at 400 kHz and 10 MHz (100 ns cycles): request 1, START t_HD;STA 600 ns = 6,
    # four 9-bit frames of 25 (address, register, address, data), repeated START
    # t_LOW 1600 ns + t_SU;STA 600 + t_HD;STA 600 = 28, STOP t_LOW + t_SU;STO 600 + t_BUF
    # 1300 = 35.
    assert who[0] == 1 + 6 + 4 * 9 * 25 + 28 + 35
    assert who[0] == ctrl.transfer_cycles(1, 1)
    assert write[0] == 1 + 6 + 3 * 9 * 25 + 35 == ctrl.transfer_cycles(2, 0)
    assert refused[2] in (0, 1)  # the IST8310 model decides; the index is checked in cocotb


def test_pwm_generator_widths_take_effect_at_the_next_period():
    gen = PwmGenerator()

    async def bench(ctx):
        ctx.set(gen.width_ticks, [3, 0, 10, 5, 0, 0, 0, 1])
        ctx.set(gen.period_ticks, 10)
        levels = []
        for cycle in range(35):
            if cycle == 14:  # mid-period: must not touch the running pulse
                ctx.set(gen.width_ticks, [7, 0, 10, 5, 0, 0, 0, 1])
            await ctx.tick()
            levels.append(ctx.get(gen.pwm.pulses))
        return levels

    levels = run(gen, bench)
    high = [[lv >> ch & 1 for lv in levels] for ch in range(8)]
    assert high[0][:30] == [1] * 3 + [0] * 7 + [1] * 3 + [0] * 7 + [1] * 7 + [0] * 3
    assert sum(high[1]) == 0
    assert all(high[2])
    assert sum(high[7][:30]) == 3
