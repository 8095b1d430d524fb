"""cocotb bench for SensorTop's SPI chips: interface timing against the datasheets,
coherence against host updates, drivers over RTL equal to drivers over the TLM.

Run from ``test_cosim_spi.py`` on every simulator. One bench class owns the clock, the
host port, the SPI controller and the reference models; every check compares the RTL
with the models or with datasheet numbers.
"""

import os

import cocotb
import numpy as np
from cocotb.triggers import Timer
from cocotb.utils import get_sim_time

from fpga_hdl.buses.transactions import TlmSpiBus
from fpga_hdl.chips.mpu6000 import regs as mpu
from fpga_hdl.chips.mpu6000.driver import Mpu6000Driver
from fpga_hdl.chips.mpu6000.model import Mpu6000Model
from fpga_hdl.chips.ms5611 import regs as baro_regs
from fpga_hdl.chips.ms5611.driver import Ms5611Driver
from fpga_hdl.chips.ms5611.model import Ms5611Model, raw_from_si
from fpga_hdl.cosim.sensor_top import SensorTopPins
from fpga_hdl.top import SYS_CLK_HZ
from fpga_hdl.verification.scoreboard import ScoredSpiBus
from fpga_hdl.verification.spi_master import DEFAULT_TIMING, SpiMasterTiming

SEED = int(os.environ.get("COSIM_SEED", "20240611"))


class SensorTopBench:
    """Host port + SPI controller on the DUT, with TLM models fed the same samples."""

    def __init__(self, dut, timing: SpiMasterTiming = DEFAULT_TIMING) -> None:
        pins = SensorTopPins(dut, spi_timing=timing)
        self.host, self.spi = pins.host, pins.spi
        self.imu_model = Mpu6000Model()
        self.baro_model = Ms5611Model()
        #: Every transfer on RTL and TLM, scored byte for byte.
        self.bus = ScoredSpiBus(
            self.spi, TlmSpiBus({"imu": self.imu_model, "baro": self.baro_model})
        )
        self.now_us = 1

    async def start(self) -> None:
        await self.host.reset()
        await self.host.load({}, now_us=self.now_us)

    async def load_imu(self, sample: mpu.Mpu6000Sample, **kwargs) -> None:
        await self.host.load({"imu": sample.fields()}, **kwargs)
        self.imu_model.load_sample(sample)

    async def load_baro(self, d1: int, d2: int) -> None:
        await self.host.load({"baro": {"d1": d1, "d2": d2}})
        self.baro_model.load_sample(d1, d2)

    async def sleep_us(self, us: int) -> None:
        """Advance simulated time for the chips (no clock runs while it passes)."""
        self.now_us += us
        self.baro_model.now_us = self.now_us
        await self.host.load({}, now_us=self.now_us)

    async def both(self, tx: bytes, device: str, sclk_hz: float) -> bytes:
        """The same transfer on RTL and TLM, scored."""
        return await self.bus.transfer(device, tx, sclk_hz=sclk_hz)


def random_imu_sample(rng) -> mpu.Mpu6000Sample:
    limit = 1 << (mpu.SAMPLE_BITS - 1)
    values = [int(v) for v in rng.integers(-limit, limit, 7)]
    values[3] = int(rng.integers(-32768, 32768))
    return mpu.Mpu6000Sample(*values)


@cocotb.test()
async def modes_at_datasheet_sclk_limits(dut):
    """Modes 0 and 3: registers at 1 MHz, sensor data at 20 MHz (PS-MPU-6000A-00 §6.4),
    MS5611 PROM and ADC at 20 MHz; every byte equals the TLM's."""
    rng = np.random.default_rng(SEED)
    for mode in (0, 3):
        bench = SensorTopBench(dut, SpiMasterTiming(mode=mode))
        await bench.start()
        limits = mpu.SPI_TIMING
        who = await bench.both(bytes([0x75 | 0x80, 0]), "imu", limits.sclk_max_all_registers_hz)
        assert who[1] == 0x68
        for register, value in ((0x6B, 0x01), (0x1B, 0x10), (0x1C, 0x08)):
            await bench.both(bytes([register, value]), "imu", limits.sclk_max_all_registers_hz)
        await bench.both(bytes([0x1B | 0x80, 0, 0]), "imu", limits.sclk_max_all_registers_hz)
        for _ in range(3):
            await bench.load_imu(random_imu_sample(rng))
            burst = bytes([0x3B | 0x80]) + bytes(14)
            await bench.both(burst, "imu", limits.sclk_max_sensor_registers_hz)
        for word in range(8):
            prom = await bench.both(bytes([0xA0 + 2 * word, 0, 0]), "baro", baro_regs.SCLK_MAX_HZ)
            assert int.from_bytes(prom[1:], "big") == baro_regs.DEFAULT_PROM[word]


@cocotb.test()
async def miso_changes_only_on_falling_sclk_edges(dut):
    """SDO valid timing: within a selected transfer SDO changes only at falling SCLK
    edges (0 ns ≤ t_VD.SDO = 100 ns) and holds through the rising edge (t_HD.SDO)."""
    for mode in (0, 3):
        bench = SensorTopBench(dut, SpiMasterTiming(mode=mode))
        await bench.start()
        await bench.both(bytes([0x6B, 0x01]), "imu", 1e6)
        await bench.load_imu(mpu.Mpu6000Sample(0x5A5A5, -0x2D2D3, 0x1234, -77, 0x3C3C3, 0x7FFF, -1))
        falls, changes = [], []

        async def watch(signal, into):
            while True:
                await (signal.falling_edge if signal is dut.spi_sclk else signal.value_change)
                if not int(dut.imu_cs_n.value):
                    into.append(get_sim_time(unit="ps"))

        tasks = [
            cocotb.start_soon(watch(dut.spi_sclk, falls)),
            cocotb.start_soon(watch(dut.spi_miso, changes)),
        ]
        await bench.both(bytes([0x3B | 0x80]) + bytes(14), "imu", 20e6)
        for task in tasks:
            task.cancel()
        assert len(changes) >= 16, f"the pattern toggled SDO only {len(changes)} times"
        fall_set = set(falls)
        late = [t for t in changes if t not in fall_set]
        assert not late, f"mode {mode}: SDO changed away from a falling SCLK edge at {late[:5]} ps"


@cocotb.test()
async def cs_setup_and_hold_at_datasheet_minimum(dut):
    """t_SU.CS = 8 ns and t_HD.CS = 500 ns (PS-MPU-6000A-00 §6.8), CS idle one half
    period: back-to-back transfers alternating chips all read correctly."""
    timing = SpiMasterTiming(mode=3, cs_setup_s=8e-9, cs_hold_s=500e-9, cs_idle_s=25e-9)
    bench = SensorTopBench(dut, timing)
    await bench.start()
    await bench.both(bytes([0x6B, 0x01]), "imu", 1e6)
    await bench.load_imu(mpu.Mpu6000Sample(1, 2, 3, 4, 5, 6, 7))
    for _ in range(4):
        await bench.both(bytes([0x3B | 0x80]) + bytes(14), "imu", 20e6)
        await bench.both(bytes([0xA2, 0, 0]), "baro", 20e6)
    assert not int(dut.spi_contention.value)


@cocotb.test()
async def transfer_aborted_mid_byte_leaves_chips_ready(dut):
    bench = SensorTopBench(dut)
    await bench.start()
    for cs_n, bits in ((dut.imu_cs_n, 5), (dut.baro_cs_n, 11), (dut.imu_cs_n, 13)):
        cs_n.value = 0
        await Timer(50, unit="ns")
        for _ in range(bits):
            dut.spi_mosi.value = 1
            await Timer(25, unit="ns")
            dut.spi_sclk.value = 1
            await Timer(25, unit="ns")
            dut.spi_sclk.value = 0
        cs_n.value = 1
        await Timer(100, unit="ns")
        who = await bench.spi.transfer("imu", bytes([0xF5, 0]), sclk_hz=1e6)
        prom = await bench.spi.transfer("baro", bytes([0xA2, 0, 0]), sclk_hz=20e6)
        assert who == bytes([0, 0x68])
        assert int.from_bytes(prom[1:], "big") == baro_regs.DEFAULT_PROM[1]


@cocotb.test()
async def read_racing_host_update_is_never_mixed(dut):
    """Randomised and seeded: with the system clock free-running, as on an FPGA, a
    commit at any moment around a 20 MHz burst yields the old sample or the new one,
    never a mix, and both outcomes occur. The new sample is staged before the burst:
    staging alone must never show."""
    rng = np.random.default_rng(SEED + 1)
    bench = SensorTopBench(dut)
    await bench.start()
    await bench.both(bytes([0x6B, 0x01]), "imu", 1e6)
    burst_ps = 15 * 8 * 50_000
    cycle_ps = round(1e12 / SYS_CLK_HZ)
    outcomes = set()
    for trial in range(12):
        old, new = random_imu_sample(rng), random_imu_sample(rng)
        await bench.load_imu(old)
        await bench.host.stage({"imu": new.fields()})
        old_bytes = mpu.data_register_bytes(old, 0, 0)
        new_bytes = mpu.data_register_bytes(new, 0, 0)
        lead_ps = int(rng.integers(0, 8 * cycle_ps))  # commit up to 8 cycles before CS falls
        offset_ps = int(rng.integers(0, burst_ps)) if trial % 2 else 0

        async def free_running_clock():
            while True:
                await bench.host.cycles(1)

        async def racing_commit(offset_ps=offset_ps):
            await Timer(offset_ps + 1, unit="ps")
            await dut.clk.falling_edge
            dut.commit.value = 1
            await dut.clk.falling_edge
            dut.commit.value = 0

        clock = cocotb.start_soon(free_running_clock())
        if offset_ps == 0:
            race = cocotb.start_soon(racing_commit())
            await Timer(lead_ps + 1, unit="ps")
        else:
            race = cocotb.start_soon(racing_commit())
        rx = await bench.spi.transfer("imu", bytes([0x3B | 0x80]) + bytes(14), sclk_hz=20e6)
        await race
        clock.cancel()
        dut.clk.value = 0
        await bench.host.settle()
        assert rx[1:] in (old_bytes, new_bytes), f"trial {trial}: mixed sample {rx.hex()}"
        outcomes.add(rx[1:] == new_bytes)
        bench.imu_model.load_sample(new)
        after = await bench.both(bytes([0x3B | 0x80]) + bytes(14), "imu", 20e6)
        assert after[1:] == new_bytes
    assert outcomes == {True, False}


@cocotb.test()
async def drivers_round_trip_rtl_equals_tlm(dut):
    """PX4's sequences with every transfer scored against the TLM, and SI values back
    within each chip's quantisation; then faults, again scored."""
    bench = SensorTopBench(dut)
    await bench.start()
    imu = Mpu6000Driver(bench.bus)  # every transfer of PX4's sequence scored
    await imu.start()
    rng = np.random.default_rng(SEED + 2)
    for _ in range(3):
        accel, gyro = rng.uniform(-100, 100, 3), rng.uniform(-20, 20, 3)
        await bench.load_imu(mpu.Mpu6000Sample.from_si(accel, gyro, 31.0))
        reading = await imu.read_sample()
        assert np.allclose(reading.accel_mps2, accel, atol=mpu.accel_mps2_per_lsb(0x18) * 1.1)
        assert np.allclose(reading.gyro_rads, gyro, atol=mpu.gyro_rads_per_lsb(0x18) * 1.1)

    pressure_pa, temperature_c = 95_123, 12.34
    await bench.load_baro(*raw_from_si(pressure_pa, temperature_c))
    baro = Ms5611Driver(bench.bus, bench.sleep_us)
    await baro.start()
    reading = await baro.measure()
    assert (reading.pressure_pa, reading.temperature_c) == (pressure_pa, temperature_c)

    for mute, flip in ((False, 0x81), (True, 0x00)):
        await bench.host.load({}, faults={"imu": (mute, flip)})
        bench.imu_model.fault_mute, bench.imu_model.fault_flip = mute, flip
        await bench.both(bytes([0x75 | 0x80, 0, 0]), "imu", 1e6)
