"""cocotb bench for the LIDAR-Lite v3 core on I2C: PX4's driver over RTL equal to the TLM
twin and decoded within the 1 cm resolution, the acquisition time against STATUS.BUSY,
UM10204 minimum timings in both speed modes, the auto-increment bit, address NACKs,
coherence against host updates mid-read, bus faults, and random traffic byte-identical
to the TLM model.

Run from ``test_lidarlite_cosim.py`` on every simulator, on the core alone built at
SensorTop's ``SYS_CLK_HZ``. Every byte the controller reads is checked by
:class:`~fpga_hdl.verification.i2c_master.CocotbI2cMaster` at t_VD;DAT and until SCL falls.
"""

import os
from dataclasses import replace

import cocotb
import numpy as np
import pytest
from cocotb.triggers import RisingEdge, Timer

from fpga_hdl.buses.i2c_target import FAST_MODE, STANDARD_MODE, I2cTiming
from fpga_hdl.buses.transactions import I2cNack, TlmI2cBus
from fpga_hdl.chips.lidarlite import regs
from fpga_hdl.chips.lidarlite.driver import (
    LidarLiteDriver,
    LidarLiteVersion,
    Range,
    sample_from_range,
)
from fpga_hdl.chips.lidarlite.model import LidarLiteModel
from fpga_hdl.chips.lidarlite.regs import LidarLiteSample, Register
from fpga_hdl.top import SYS_CLK_HZ
from fpga_hdl.verification.i2c_master import CocotbI2cMaster
from fpga_hdl.verification.scoreboard import ScoredI2cBus

SEED = int(os.environ.get("COSIM_SEED", "20261125"))
ADDRESS = regs.DEFAULT_ADDRESS
HALF_PERIOD_PS = round(0.5e12 / SYS_CLK_HZ)
DISTANCE = Register.FULL_DELAY_HIGH | regs.POINTER_AUTO_INCREMENT


class Bench:
    """The core with an I2C controller on its pins and the TLM twin beside it."""

    def __init__(self, dut, timing: I2cTiming | None = None) -> None:
        self.dut = dut
        self.i2c = CocotbI2cMaster(
            scl=dut.i2c__scl, sda_i=dut.i2c__sda_i, sda_oe=dut.i2c__sda_oe, clk=dut.clk,
            sys_clk_hz=SYS_CLK_HZ, timing=timing,
        )  # fmt: skip
        self.model = LidarLiteModel()
        #: :class:`I2cBus`: each transaction on the RTL and the TLM, scored byte for byte.
        self.bus = ScoredI2cBus(self.i2c, TlmI2cBus({ADDRESS: self.model}))
        self.now_us = 0

    async def cycles(self, count: int) -> None:
        """Clock the core by hand (the controller runs the clock only during transfers)."""
        for _ in range(count):
            self.dut.clk.value = 1
            await Timer(HALF_PERIOD_PS, unit="ps")
            self.dut.clk.value = 0
            await Timer(HALF_PERIOD_PS, unit="ps")

    async def start(self) -> None:
        dut = self.dut
        for name in ("sample", "sample_stb", "now_us", "fault__mute", "fault__flip"):
            getattr(dut, name).value = 0
        dut.rst.value = 1
        await self.cycles(4)
        dut.rst.value = 0
        await self.cycles(4)

    async def load(self, sample: LidarLiteSample) -> None:
        self.dut.sample.value = sample.as_register_bits()
        self.dut.sample_stb.value = 1
        await self.cycles(1)
        self.dut.sample_stb.value = 0
        await self.cycles(2)  # the latch copies it to visible
        self.model.load_sample(sample)

    def sleep_us(self, us: int) -> None:
        """Advance simulated time for the chip (no clock runs while it passes)."""
        self.now_us = (self.now_us + us) % 2**32
        self.dut.now_us.value = self.now_us
        self.model.now_us = self.now_us

    async def both(self, write: bytes, read_len: int, scl_hz: float = 400e3) -> bytes:
        return await self.bus.write_read(ADDRESS, write, read_len, scl_hz=scl_hz)

    async def status(self) -> int:
        await self.both(bytes([Register.STATUS]), 0)
        (status,) = await self.both(b"", 1)
        return status


@cocotb.test()
async def px4_driver_over_rtl_equals_tlm_within_one_centimetre(dut):
    bench = Bench(dut)
    await bench.start()
    rng = np.random.default_rng(SEED)
    driver = LidarLiteDriver(bench.bus)
    assert await driver.probe() is LidarLiteVersion.V1_V3
    await driver.reset()
    (count,) = await driver.read_register(Register.SIG_COUNT_VAL)
    assert count == 0xFF  # PX4's reset leaves the maximum acquisition count
    previous = Range(0.0, 0)  # nothing measured since power-on: 0 cm, unusable
    distances = [0.3, 1.0, *rng.uniform(0.05, 39.0, 4), 39.99, None]
    for scl_hz, distance in zip([100e3, 400e3] * 4, distances, strict=True):
        driver.scl_hz = scl_hz
        await bench.load(sample_from_range(distance))
        await driver.measure()
        assert await bench.status() & regs.STATUS_BUSY
        bench.sleep_us(regs.ACQUISITION_TIME_US - 1)
        early = await driver.collect()  # the previous result while the acquisition runs
        assert early == previous
        bench.sleep_us(1)
        assert not await bench.status() & regs.STATUS_BUSY
        result = await driver.collect()
        if distance is None:
            assert result.distance_m == regs.NO_RETURN_CM / 100
            assert result.signal_quality == 0  # below PX4's 5 cm: not used
            assert await bench.status() & regs.STATUS_INVALID_SIGNAL
        else:
            assert abs(result.distance_m - distance) <= 0.005 + 1e-9
            assert result.signal_quality == 100
        previous = result
        bench.sleep_us(50_000 - regs.ACQUISITION_TIME_US)  # PX4's 50 ms cycle
    assert len(bench.bus.scoreboard) > 60
    before = bench.i2c.cycles
    await driver.collect()
    dut._log.info(
        "PX4 ll40ls collect (3 pointer writes, 4 bytes read) at 400 kHz: %d system cycles",
        bench.i2c.cycles - before,
    )


@cocotb.test()
async def target_meets_um10204_minimum_timings_and_the_auto_increment_bit(dut):
    """Controller at the spec minimums; the target's bits are checked at t_VD;DAT."""
    sample = LidarLiteSample(0x0F5A, 0xA5, 0x3C)
    variants = []
    for mode in (STANDARD_MODE, FAST_MODE):
        variants.append(mode)  # t_HD;DAT = 0: data changes the instant SCL falls
        variants.append(replace(mode, t_hd_dat_ns=mode.t_low_ns - mode.t_su_dat_ns))
    for timing in variants:
        bench = Bench(dut, timing)
        await bench.start()
        await bench.load(sample)
        await bench.both(bytes([Register.ACQ_COMMAND, regs.ACQ_MEASURE]), 0)
        bench.sleep_us(regs.ACQUISITION_TIME_US)
        assert await bench.both(bytes([DISTANCE]), 2) == b"\x0f\x5a"
        # Without bit 7 the pointer stays: the high byte twice.
        assert await bench.both(bytes([Register.FULL_DELAY_HIGH]), 2) == b"\x0f\x0f"
        assert await bench.both(bytes([Register.PEAK_CORR | 0x80]), 5) == bytes(
            [0x3C, 0x00, 0xA5, 0x0F, 0x5A]
        )
        # A write with auto-increment fills consecutive registers (0x03 is not one: it
        # ignores the byte and reads 0).
        await bench.both(bytes([Register.SIG_COUNT_VAL | 0x80, 0x11, 0x22, 0x33]), 0)
        assert await bench.both(bytes([Register.SIG_COUNT_VAL | 0x80]), 3) == b"\x11\x00\x33"


@cocotb.test()
async def wrong_address_is_nacked_and_next_transfer_works(dut):
    bench = Bench(dut)
    await bench.start()
    for address in (0x42, 0x0E, 0x63, 0x77):  # 0x42: the old address PX4 also probes
        with pytest.raises(I2cNack) as nack:
            await bench.i2c.write_read(address, bytes([Register.STATUS]), 1, scl_hz=400e3)
        assert (nack.value.address, nack.value.byte_index) == (address, 0)
    assert await bench.both(bytes([Register.HW_VERSION]), 1) == b"\x01"


@cocotb.test()
async def fault_mute_nacks_and_fault_flip_xors_sent_bytes(dut):
    bench = Bench(dut)
    await bench.start()
    dut.fault__flip.value = bench.model.fault_flip = 0x5A
    assert await bench.both(bytes([Register.SIG_COUNT_VAL]), 1) == bytes([0x80 ^ 0x5A])
    dut.fault__flip.value = bench.model.fault_flip = 0
    dut.fault__mute.value = 1
    with pytest.raises(I2cNack):
        await bench.i2c.write_read(ADDRESS, bytes([Register.STATUS]), 1, scl_hz=400e3)
    dut.fault__mute.value = 0
    assert await bench.both(bytes([Register.SIG_COUNT_VAL]), 1) == b"\x80"


async def host_update_on_the_running_clock(dut, sample: LidarLiteSample) -> None:
    await RisingEdge(dut.clk)
    dut.sample.value = sample.as_register_bits()
    dut.sample_stb.value = 1
    await RisingEdge(dut.clk)
    dut.sample_stb.value = 0


@cocotb.test()
async def acquire_racing_host_updates_measures_one_whole_sample(dut):
    """A sample offered while the acquire command is on the bus: the acquisition measures
    the old or the new sample whole (an offer after the address ACK waits for the STOP),
    and the next acquisition measures the new one."""
    rng = np.random.default_rng(SEED)
    bench = Bench(dut)
    await bench.start()
    i2c, outcomes = bench.i2c, {"old": 0, "new": 0}

    async def distance_after_acquire() -> bytes:
        await i2c.write_read(ADDRESS, bytes([Register.ACQ_COMMAND, regs.ACQ_MEASURE]), 0,
                             scl_hz=400e3)  # fmt: skip
        bench.sleep_us(regs.ACQUISITION_TIME_US)
        return await i2c.write_read(ADDRESS, bytes([DISTANCE]), 2, scl_hz=400e3)

    for _ in range(10):
        old, new = (LidarLiteSample(int(rng.integers(0, 0x8000)), 100, 200) for _ in range(2))
        await bench.load(old)
        delay_ns = int(rng.integers(0, 60_000))  # START to STOP of the command: ~70 µs

        async def racer(new=new, delay_ns=delay_ns):
            await Timer(delay_ns, unit="ns")
            await host_update_on_the_running_clock(dut, new)

        racer_task = cocotb.start_soon(racer())
        measured = await distance_after_acquire()
        await racer_task
        which = [k for k, s in (("old", old), ("new", new))
                 if measured == s.distance_cm.to_bytes(2, "big")]  # fmt: skip
        assert which, f"{measured.hex()} is neither {old} nor {new} (offer at {delay_ns} ns)"
        outcomes[which[0]] += 1
        assert await distance_after_acquire() == new.distance_cm.to_bytes(2, "big")
    dut._log.info("acquisitions racing host updates: %s", outcomes)
    assert min(outcomes.values()) > 0, outcomes


def random_transactions(rng: np.random.Generator, count: int):
    """Traffic a driver could send: pointers with and without bit 7, acquire and reset
    commands, configuration writes, reads of every register, time steps around the
    acquisition time."""
    registers = [int(r) for r in Register] + [0x03, 0x61, 0x7F]
    for _ in range(count):
        pointer = int(rng.choice(registers)) | int(rng.integers(2)) << 7
        kind = int(rng.integers(4))
        step_us = int(rng.choice([0, regs.ACQUISITION_TIME_US // 2, regs.ACQUISITION_TIME_US,
                                  int(rng.integers(0, 20_000))]))  # fmt: skip
        if kind == 0:
            command = int(rng.choice([regs.ACQ_MEASURE, regs.ACQ_MEASURE_NO_BIAS, regs.ACQ_RESET]))
            yield step_us, bytes([Register.ACQ_COMMAND, command]), 0
        elif kind == 1:
            payload = rng.integers(0, 256, size=int(rng.integers(1, 4))).tolist()
            yield step_us, bytes([pointer, *payload]), 0
        else:
            yield step_us, bytes([pointer]), int(rng.integers(1, 6))


@cocotb.test()
async def random_traffic_rtl_equals_tlm(dut):
    rng = np.random.default_rng(SEED + 1)
    bench = Bench(dut)
    await bench.start()
    bench.sleep_us(2**32 - 30_000)  # acquisitions span the 32-bit wrap of now_us
    reads = []
    for step_us, write, read_len in random_transactions(rng, 60):
        bench.sleep_us(step_us)
        if rng.integers(3) == 0:
            await bench.load(LidarLiteSample(*(int(rng.integers(0, 1 << b)) for b in (16, 8, 8))))
        reads.append(await bench.both(write, read_len))
    assert any(r and r != bytes(len(r)) for r in reads)  # the traffic really read data
