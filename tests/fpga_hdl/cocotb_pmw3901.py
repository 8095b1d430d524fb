"""cocotb bench for the PMW3901 optical-flow chip on SensorTop's shared SPI bus: PX4's
pmw3901 driver over RTL equal to the TLM twin byte for byte (init sequence and motion
reads), the motion burst, accumulation, saturation and clear-on-read, the datasheet's SPI
timing at its limits (SDO valid timing, t_SRAD, t_SRW/t_SRR, t_SWW, t_SWR, t_BEXIT,
t_NCS-SCLK, t_SCLK-NCS), faults, random traffic, and the IMU and barometer answering
beside it.

Run from ``test_pmw3901_cosim.py`` on every simulator. The system clock runs only while
the host port works (:class:`~fpga_hdl.cosim.host.CocotbHost`), so the chip's bus side
and its accumulators meet as on a gated co-simulation; the host-update race is
``cocotb_sensor_top``'s, on the same latch.
"""

import os
from dataclasses import replace

import cocotb
import numpy as np
from cocotb.triggers import ReadOnly
from cocotb.utils import get_sim_time

from fpga_hdl.buses.transactions import TlmSpiBus
from fpga_hdl.chips.mpu6000.driver import Mpu6000Driver
from fpga_hdl.chips.mpu6000.model import Mpu6000Model
from fpga_hdl.chips.mpu6000.regs import Mpu6000Sample
from fpga_hdl.chips.ms5611.driver import Ms5611Driver
from fpga_hdl.chips.ms5611.model import Ms5611Model, raw_from_si
from fpga_hdl.chips.pmw3901 import regs
from fpga_hdl.chips.pmw3901.driver import MOTION_READ, Pmw3901Driver, motion_read
from fpga_hdl.chips.pmw3901.model import Pmw3901Model
from fpga_hdl.chips.pmw3901.regs import Pmw3901Sample, Reg
from fpga_hdl.cosim.sensor_top import SensorTopPins
from fpga_hdl.verification.scoreboard import ScoredSpiBus
from fpga_hdl.verification.spi_master import SpiMasterTiming

SEED = int(os.environ.get("COSIM_SEED", "20261129"))
LIMITS = regs.SPI_TIMING
SCLK_HZ = LIMITS.sclk_max_hz
PERIOD_S = 1 / SCLK_HZ
#: The datasheet's mode 3 with its chip-select limits after a read.
READ_TIMING = SpiMasterTiming(
    mode=LIMITS.mode, cs_setup_s=LIMITS.ncs_sclk_min_s, cs_hold_s=LIMITS.sclk_ncs_read_min_s,
    cs_idle_s=LIMITS.bexit_min_s,
)  # fmt: skip
WRITE_TIMING = replace(READ_TIMING, cs_hold_s=LIMITS.sclk_ncs_write_min_s)


class FlowBench:
    """SensorTop's pins; the three SPI chips' TLM twins on one TLM bus beside them."""

    def __init__(self, dut, timing: SpiMasterTiming = READ_TIMING) -> None:
        pins = SensorTopPins(dut, spi_timing=timing)
        self.dut, self.host, self.spi = dut, pins.host, pins.spi
        self.flow, self.imu, self.baro = Pmw3901Model(), Mpu6000Model(), Ms5611Model()
        tlm = TlmSpiBus({"flow": self.flow, "imu": self.imu, "baro": self.baro})
        #: Every transfer on RTL and TLM, scored byte for byte.
        self.bus = ScoredSpiBus(self.spi, tlm)
        self.driver = Pmw3901Driver(self.bus)

    async def start(self, *, init: bool = True) -> None:
        await self.host.reset()
        await self.host.load({}, now_us=1)
        if init:
            assert await self.driver.probe()
            await self.driver.init()
            assert self.flow.tracking

    async def load(self, sample: Pmw3901Sample) -> None:
        await self.host.load({"flow": sample.fields()})
        self.flow.load_sample(sample)

    async def faults(self, mute: bool = False, flip: int = 0, own: int = 0) -> None:
        await self.host.load({}, faults={"flow": (mute, flip, own)})
        self.flow.fault_mute, self.flow.fault_flip, self.flow.fault_own = mute, flip, own

    async def both(self, tx: bytes) -> bytes:
        return await self.bus.transfer("flow", tx, sclk_hz=SCLK_HZ)

    async def read_banked(self, bank: int, register: int) -> int:
        await self.driver.write_register(Reg.BANK_SELECT, bank)
        value = await self.driver.read_register(register)
        await self.driver.write_register(Reg.BANK_SELECT, 0)
        return value


def random_frame(rng: np.random.Generator, span: int = 300) -> Pmw3901Sample:
    """A camera frame; deltas beyond PX4's ±240 now and then, zero motion too."""
    dx, dy = (int(v) for v in rng.integers(-span, span + 1, 2).clip(-32768, 32767))
    if rng.integers(6) == 0:
        dx = dy = 0
    return Pmw3901Sample(dx, dy, int(rng.integers(0, 256)), int(rng.integers(0, 1 << 13)),
                         *(int(v) for v in rng.integers(0, 256, 3)))  # fmt: skip


@cocotb.test()
async def px4_driver_over_rtl_equals_tlm(dut):
    """PX4's probe, sensorInit (every register it writes read back, PX4's branch values)
    and 40 RunImpl cycles with 0..3 camera frames between them, scored byte for byte."""
    rng = np.random.default_rng(SEED)
    bench = FlowBench(dut)
    await bench.start()
    stored = bench.flow.stored
    for (bank, register), value in stored.items():
        assert await bench.read_banked(bank, register) == value
    # PX4's branches on the trim reads: 0x67 bit 7 set → 0x04; 0x73 = 0 → c1, c2 written.
    assert stored[(0x0E, 0x48)] == 0x04
    assert (stored[(0x0E, 0x70)], stored[(0x0E, 0x71)]) == (0x1A + 14, 0x40 * 45 // 100)
    assert (stored[(0x00, 0x40)], stored[(0x00, 0x55)], stored[(0x07, 0x40)]) == (0x80, 0x80, 0x40)
    reports = []
    for cycle in range(40):
        for _ in range(int(rng.integers(0, 4))):
            await bench.load(random_frame(rng))
        report = await bench.driver.cycle(10_000 * (cycle + 1))
        if report is not None:
            reports.append(report)
    assert len(reports) == 20  # every second 10 ms cycle closes a 20 ms window
    assert {r.integration_timespan_us for r in reports} == {20_000}
    assert any(r.quality for r in reports)
    assert any(r.pixel_flow_rad != (0.0, 0.0) for r in reports)
    assert len(bench.bus.scoreboard) > 200


@cocotb.test()
async def burst_accumulation_saturation_and_clear_on_read(dut):
    bench = FlowBench(dut)
    await bench.start()
    frames = [Pmw3901Sample(30_000, -30_000, 40, 0x1ABC, 1, 2, 3),
              Pmw3901Sample(30_000, -30_000, 77, 0x0123, 4, 5, 6)]  # fmt: skip
    for frame in frames:
        await bench.load(frame)
    burst = await bench.both(bytes([Reg.MOTION_BURST]) + bytes(regs.BURST_LENGTH + 2))
    # Saturated at int16, the last frame's image, then zeros past the 12 bytes.
    assert burst[1:] == bytes([0x80, regs.OBSERVATION_TRACKING]) + (32767).to_bytes(2, "little") + (
        -32768
    ).to_bytes(2, "little", signed=True) + bytes([77, 4, 5, 6, 0x01, 0x23, 0, 0])
    # The burst cleared the accumulators and its Delta bytes: nothing moved since.
    assert motion_read(await bench.both(MOTION_READ)) == (0, 0, 77)
    await bench.load(Pmw3901Sample(5, -7, 50, 0))
    # Delta read before Motion: the old (read, so cleared) values; Motion freezes, the
    # Delta registers answer once each, byte by byte.
    assert await bench.both(bytes([Reg.DELTA_X_L, 0, Reg.DELTA_X_H, 0])) == bytes(4)
    rx = await bench.both(MOTION_READ)
    assert rx[1] == regs.MOTION_MOT
    assert motion_read(rx) == (5, -7, 50)
    assert await bench.both(bytes([Reg.DELTA_X_L, 0, Reg.DELTA_Y_H, 0])) == bytes(4)
    # A second Motion read before the Delta reads loses the first values.
    await bench.load(Pmw3901Sample(9, 9, 50, 0))
    await bench.both(bytes([Reg.MOTION, 0]))
    await bench.both(bytes([Reg.MOTION, 0]))
    assert motion_read(await bench.both(MOTION_READ)) == (0, 0, 50)


@cocotb.test()
async def spi_timing_at_the_datasheet_limits(dut):
    """Mode 3 at 2 MHz with every gap at its minimum: t_SRAD after each read address,
    t_SRR/t_SRW after each read's data, t_SWW between writes, t_SWR from a write to a
    read, a motion burst read t_SRAD after its address and left t_BEXIT before the next
    transfer, t_NCS-SCLK and t_SCLK-NCS around every transfer. SDO changes only at
    falling SCLK edges while selected (valid 0 ns after, within t_DLY = 120 ns) and is
    released the moment NCS rises."""
    bench = FlowBench(dut)
    await bench.start()
    await bench.load(Pmw3901Sample(-3, 100, 99, 0x1FFF))
    half = PERIOD_S / 2
    # Inter-byte gaps the master adds to its half period after a byte's last rising edge.
    srad = LIMITS.srad_min_s - half
    srr = LIMITS.srw_srr_min_s - half
    sww = LIMITS.sww_min_s - 16 * PERIOD_S  # last data bit to the next write's last bit
    swr = LIMITS.swr_min_s - 8 * PERIOD_S  # last data bit to the read address's last bit
    falls, changes, released = [], [], []

    async def watch_falls():
        while True:
            await dut.spi_sclk.falling_edge
            if not int(dut.flow_cs_n.value):
                falls.append(get_sim_time(unit="ps"))

    async def watch_miso():
        while True:
            await dut.spi_miso.value_change
            if not int(dut.flow_cs_n.value):
                changes.append(get_sim_time(unit="ps"))

    async def watch_release():
        while True:
            await dut.flow_cs_n.rising_edge
            await ReadOnly()  # the time step's logic settled
            released.append(int(dut.spi_miso_oe.value))

    tasks = [cocotb.start_soon(w()) for w in (watch_falls, watch_miso, watch_release)]

    async def scored(tx: bytes, gaps: list[float], timing: SpiMasterTiming) -> bytes:
        bench.spi.timing = timing
        rx = await bench.spi.transfer("flow", tx, sclk_hz=SCLK_HZ, gaps_s=gaps)
        bench.bus.scoreboard.check(f"flow {tx.hex()}", bench.flow.transfer(tx), rx)
        return rx

    reads = bytes([Reg.PRODUCT_ID, 0, Reg.INVERSE_PRODUCT_ID, 0, Reg.SQUAL, 0])
    rx = await scored(reads, [srad, srr, srad, srr, srad], READ_TIMING)
    assert rx[1::2] == bytes([0x49, 0xB6, 99])
    writes = bytes([Reg.BANK_SELECT | 0x80, 0x07, 0x41 | 0x80, 0x5C, Reg.BANK_SELECT | 0x80, 0])
    await scored(writes, [0, sww, 0, sww, 0], WRITE_TIMING)
    back = bytes([Reg.BANK_SELECT | 0x80, 0x07, 0x41, 0, Reg.BANK_SELECT | 0x80, 0])
    assert (await scored(back, [0, swr, srad, srr, 0], WRITE_TIMING))[3] == 0x5C
    gaps = [srad if i % 2 == 0 else srr for i in range(len(MOTION_READ) - 1)]
    assert motion_read(await scored(MOTION_READ, gaps, READ_TIMING)) == (-3, 100, 99)
    await bench.load(Pmw3901Sample(-3, 100, 99, 0x1FFF))
    burst = await scored(bytes([Reg.MOTION_BURST]) + bytes(12), [srad], READ_TIMING)
    assert burst[1] == regs.MOTION_MOT
    assert burst[3:7] == bytes.fromhex("fdff6400")
    assert (await scored(bytes([Reg.PRODUCT_ID, 0]), [srad], READ_TIMING))[1] == 0x49
    for task in tasks:
        task.cancel()
    late = sorted(set(changes) - set(falls))
    assert len(changes) > 20
    assert not late, f"SDO changed away from a falling edge at {late[:5]}"
    assert released
    assert not any(released), "SDO still driven after NCS rose"


@cocotb.test()
async def faults_rtl_equals_tlm(dut):
    """Mute and flip as every chip; stuck keeps the pre-fault motion and the old SQUAL,
    zero_quality reads SQUAL 0 and PX4 drops the read, drop_frames discards motion."""
    bench = FlowBench(dut)
    await bench.start()
    frame = Pmw3901Sample(12, -4, 80, 0x0444)
    await bench.faults(flip=0x0F)
    await bench.load(frame)
    assert motion_read(bytes(b ^ 0x0F for b in await bench.both(MOTION_READ))) == (12, -4, 80)
    await bench.faults(mute=True)
    assert await bench.both(MOTION_READ) == b"\xff" * len(MOTION_READ)
    await bench.faults()
    await bench.load(frame)
    await bench.faults(own=regs.FAULT_STUCK)
    await bench.load(Pmw3901Sample(50, 50, 10, 0))  # not taken: the image froze
    assert motion_read(await bench.both(MOTION_READ)) == (12, -4, 80)
    assert motion_read(await bench.both(MOTION_READ)) == (0, 0, 80)
    await bench.faults(own=regs.FAULT_ZERO_QUALITY)
    await bench.load(frame)
    assert motion_read(await bench.both(MOTION_READ)) == (12, -4, 0)
    await bench.faults()
    await bench.load(frame)
    await bench.faults(own=regs.FAULT_DROP_FRAMES)
    await bench.load(frame)
    rx = await bench.both(MOTION_READ)
    assert rx[1] == 0
    assert motion_read(rx) == (0, 0, 80)
    await bench.faults()
    await bench.load(frame)
    assert motion_read(await bench.both(MOTION_READ)) == (12, -4, 80)


def random_transfer(rng: np.random.Generator) -> bytes:
    """Traffic a driver could send: pairs to any register (bank select, power-up reset,
    shutdown, the optimisation's last write among them), bursts of any length."""
    if rng.integers(6) == 0:
        return bytes([Reg.MOTION_BURST]) + bytes(int(rng.integers(0, 15)))
    registers = [int(r) for r in Reg] + [0x40, 0x48, 0x55, 0x67, 0x70, 0x73, 0x20, 0x7E]
    tx = bytearray()
    for _ in range(int(rng.integers(1, 5))):
        register = int(rng.choice(registers))
        write = rng.integers(3) == 0
        value = int(rng.choice([0, 0x07, 0x0E, 0x80, 0x5A, 0xB6, int(rng.integers(256))]))
        tx += bytes([register | 0x80 * int(write), value if write else 0])
    return bytes(tx[: len(tx) - int(rng.integers(2))])  # now and then a lone address


@cocotb.test()
async def random_traffic_rtl_equals_tlm(dut):
    rng = np.random.default_rng(SEED + 1)
    bench = FlowBench(dut)
    await bench.start()
    for step in range(150):
        if rng.integers(3) == 0:
            await bench.load(random_frame(rng, 40_000))
        if step % 40 == 39:
            await bench.faults(own=int(rng.integers(0, 8)), flip=int(rng.integers(2)) * 0x33)
        if step == 100:  # the chip back to tracking, to see frames again
            await bench.faults()
            await bench.driver.init()
        await bench.both(random_transfer(rng))
    assert len(bench.bus.scoreboard) > 150


@cocotb.test()
async def imu_and_baro_answer_beside_the_flow_chip(dut):
    """PX4's MPU-6000, MS5611 and PMW3901 drivers interleaved on the shared bus, every
    transfer scored; a muted flow chip leaves the other two answering; no contention."""
    rng = np.random.default_rng(SEED + 2)
    bench = FlowBench(dut)
    await bench.start()
    imu = Mpu6000Driver(bench.bus)
    await imu.start()
    now_us = 1

    async def sleep_us(us: int) -> None:
        nonlocal now_us
        now_us += us
        bench.baro.now_us = now_us
        await bench.host.load({}, now_us=now_us)

    d1, d2 = raw_from_si(95_000, 21.0)
    await bench.host.load({"baro": {"d1": d1, "d2": d2}})
    bench.baro.load_sample(d1, d2)
    baro = Ms5611Driver(bench.bus, sleep_us)
    await baro.start()
    for cycle in range(6):
        if cycle == 3:
            await bench.faults(mute=True)
        sample = Mpu6000Sample(*(int(v) for v in rng.integers(-1000, 1000, 7)))
        await bench.host.load({"imu": sample.fields()})
        bench.imu.load_sample(sample)
        await bench.load(random_frame(rng))
        await imu.read_raw()
        await bench.driver.cycle(10_000 * cycle)
        reading = await baro.measure()
        assert reading.pressure_pa == 95_000
    assert not int(dut.spi_contention.value)
