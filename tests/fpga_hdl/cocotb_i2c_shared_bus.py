"""cocotb bench for SensorTop's shared I2C bus: the IST8310 (0x0E) and the LIDAR-Lite v3
(0x62) as two targets on one SCL/SDA pair, as on a Pixhawk's external I2C port.

Run from ``test_cosim_i2c.py`` on every simulator. PX4's two drivers interleave their
transactions on the bus; every byte equals the TLM twins' on one TLM bus; a bus fault on
one target leaves the other alone.
"""

import os

import cocotb
import numpy as np
import pytest

from fpga_hdl.buses.transactions import I2cNack, TlmI2cBus
from fpga_hdl.chips.ist8310 import regs as ist_regs
from fpga_hdl.chips.ist8310.driver import Ist8310Driver, sample_from_field_gauss
from fpga_hdl.chips.ist8310.model import Ist8310Model
from fpga_hdl.chips.lidarlite import regs as lidar_regs
from fpga_hdl.chips.lidarlite.driver import LidarLiteDriver, LidarLiteVersion, sample_from_range
from fpga_hdl.chips.lidarlite.model import LidarLiteModel
from fpga_hdl.cosim.sensor_top import SensorTopPins
from fpga_hdl.verification.scoreboard import ScoredI2cBus

SEED = int(os.environ.get("COSIM_SEED", "20261125"))


class SharedBus:
    """SensorTop's I2C pins with both TLM twins on one TLM bus beside them."""

    def __init__(self, dut) -> None:
        pins = SensorTopPins(dut)
        self.host, self.i2c = pins.host, pins.i2c
        self.mag, self.range = Ist8310Model(), LidarLiteModel()
        tlm = TlmI2cBus({self.mag.address: self.mag, self.range.address: self.range})
        self.scored = ScoredI2cBus(self.i2c, tlm)
        self.now_us = 1
        self.transactions = {self.mag.address: 0, self.range.address: 0}

    async def start(self) -> None:
        await self.host.reset()
        await self.host.load({}, now_us=self.now_us)

    async def load(self, field_gauss, distance_m) -> None:
        mag, ranged = sample_from_field_gauss(field_gauss), sample_from_range(distance_m)
        fields = {"x": mag.x_counts, "y": mag.y_counts, "z": mag.z_counts}
        await self.host.load({"mag": fields, "range": ranged.fields()})
        self.mag.load_sample(mag)
        self.range.load_sample(ranged)

    async def sleep_us(self, us: int) -> None:
        self.now_us += us
        self.mag.now_us = self.range.now_us = self.now_us
        await self.host.load({}, now_us=self.now_us)

    async def write_read(self, address, write, read_len, *, scl_hz):
        """:class:`I2cBus`: the RTL bus and the TLM bus scored, counted per target."""
        self.transactions[address] += 1
        return await self.scored.write_read(address, write, read_len, scl_hz=scl_hz)


@cocotb.test()
async def px4_drivers_of_both_targets_interleave_on_one_bus(dut):
    bus = SharedBus(dut)
    await bus.start()
    mag, lidar = Ist8310Driver(bus), LidarLiteDriver(bus)
    assert await mag.probe()
    assert await lidar.probe() is LidarLiteVersion.V1_V3
    await mag.reset()
    await lidar.reset()
    await bus.sleep_us(50_000)
    assert await mag.reset_done()
    assert await mag.configure()
    rng = np.random.default_rng(SEED)
    await lidar.measure()
    previous = None
    for _ in range(4):  # PX4's cycles: the mag every 20 ms, the lidar every 50 ms
        field = tuple(rng.uniform(-0.6, 0.6, 3))
        distance = float(rng.uniform(0.1, 24.0))
        await bus.load(field, distance)
        await mag.start_measurement()
        ranged = await lidar.collect()
        await lidar.measure()  # measures the distance just loaded
        await bus.sleep_us(ist_regs.MEASUREMENT_TIME_US)
        decoded = await mag.read_field_gauss()
        assert np.allclose(decoded, field, rtol=0, atol=0.5 / ist_regs.LSB_PER_GAUSS_16BIT)
        if previous is not None:
            assert abs(ranged.distance_m - previous) <= 0.005 + 1e-9
        previous = distance
        await bus.sleep_us(50_000 - ist_regs.MEASUREMENT_TIME_US)
    assert min(bus.transactions.values()) > 15


@cocotb.test()
async def a_fault_on_one_target_leaves_the_other_alone(dut):
    bus = SharedBus(dut)
    await bus.start()
    await bus.load((0.2, -0.1, 0.4), 3.21)
    lidar_id = bytes([lidar_regs.Register.HW_VERSION])
    await bus.host.load({}, faults={"range": (True, 0)})
    with pytest.raises(I2cNack) as nack:
        await bus.i2c.write_read(bus.range.address, lidar_id, 1, scl_hz=400e3)
    assert nack.value.address == bus.range.address
    wai = bytes([ist_regs.Register.WAI])
    assert await bus.i2c.write_read(bus.mag.address, wai, 1, scl_hz=400e3) == b"\x10"
    await bus.host.load({}, faults={"range": (False, 0), "mag": (False, 0xFF)})
    assert await bus.i2c.write_read(bus.mag.address, wai, 1, scl_hz=400e3) == b"\xef"
    assert await bus.i2c.write_read(bus.range.address, lidar_id, 1, scl_hz=400e3) == b"\x01"
