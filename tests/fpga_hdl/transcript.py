"""One seeded sequence of PX4 sensor transactions, run on any buses, recorded byte for byte.

The same script runs on the pin-level masters over SensorTop, on the harness's fast
peripherals and on the transaction-level models; ``test_cosim_harness`` demands three
identical transcripts. Each step loads the chips (through whatever ``Chips`` it is
given) and records every transaction as ``[bus, request hex, response hex]``.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from fpga_hdl.buses.transactions import I2cBus, I2cNack, SpiBus, TlmI2cBus, TlmSpiBus
from fpga_hdl.chips.ist8310 import regs as ist
from fpga_hdl.chips.ist8310.model import Ist8310Model
from fpga_hdl.chips.mpu6000 import regs as mpu
from fpga_hdl.chips.mpu6000.driver import SPI_SPEED_HZ, SPI_SPEED_SENSOR_HZ
from fpga_hdl.chips.mpu6000.model import Mpu6000Model
from fpga_hdl.chips.ms5611 import regs as baro
from fpga_hdl.chips.ms5611.model import Ms5611Model

SEED = 20240613
FRAMES = 6


class Chips(Protocol):
    """How a script step loads samples and time: the host port, or the models."""

    async def load(self, samples: dict[str, dict[str, int]], now_us: int) -> None: ...


def _imu_sample(rng) -> dict[str, int]:
    limit = 1 << (mpu.SAMPLE_BITS - 1)
    values = [int(v) for v in rng.integers(-limit, limit, 7)]
    values[3] = int(rng.integers(-32768, 32768))
    return mpu.Mpu6000Sample(*values).fields()


async def run_script(spi: SpiBus, i2c: I2cBus, chips: Chips) -> list[list[str]]:
    """PX4's start-up sequences, then FRAMES frames of IMU + mag + baro traffic."""
    rng = np.random.default_rng(SEED)
    log: list[list[str]] = []

    async def spi_xfer(device: str, tx: bytes, sclk_hz: float) -> bytes:
        rx = await spi.transfer(device, tx, sclk_hz=sclk_hz)
        log.append([f"spi:{device}", tx.hex(), rx.hex()])
        return rx

    async def i2c_xfer(address: int, write: bytes, read_len: int, scl_hz: float) -> None:
        try:
            rx = (await i2c.write_read(address, write, read_len, scl_hz=scl_hz)).hex()
        except I2cNack as nack:
            rx = f"nack{nack.byte_index}"
        log.append([f"i2c:{address:02x}", f"{write.hex()}+{read_len}", rx])

    now_us = 1
    await chips.load({}, now_us)
    for register, value in ((0x6B, 0x01), (0x1B, 0x18), (0x1C, 0x18), (0x1A, 0x03)):
        await spi_xfer("imu", bytes([register, value]), SPI_SPEED_HZ)
        await spi_xfer("imu", bytes([register | 0x80, 0]), SPI_SPEED_HZ)
    await spi_xfer("imu", bytes([0x75 | 0x80, 0]), SPI_SPEED_HZ)
    for word in range(8):
        await spi_xfer("baro", bytes([baro.CMD_PROM_READ + 2 * word, 0, 0]), 20e6)
    await i2c_xfer(ist.DEFAULT_ADDRESS, bytes([ist.Register.WAI]), 1, 400e3)
    await i2c_xfer(ist.DEFAULT_ADDRESS, bytes([ist.Register.CNTL3, 0x70]), 0, 100e3)
    await i2c_xfer(ist.DEFAULT_ADDRESS ^ 0x01, bytes([ist.Register.WAI]), 1, 400e3)  # absent
    for frame in range(FRAMES):
        now_us += 10_000
        d1, d2 = (int(v) for v in rng.integers(1, 1 << 24, 2))
        field = [int(v) for v in rng.integers(-32768, 32768, 3)]
        await chips.load(
            {
                "imu": _imu_sample(rng),
                "baro": {"d1": d1, "d2": d2},
                "mag": dict(zip("xyz", field, strict=True)),
            },
            now_us,
        )
        burst = bytes([0x3B | 0x80]) + bytes(14)
        await spi_xfer("imu", burst, SPI_SPEED_SENSOR_HZ)
        await i2c_xfer(ist.DEFAULT_ADDRESS, bytes([ist.Register.STAT1]), 7, 400e3)
        await i2c_xfer(ist.DEFAULT_ADDRESS, bytes([ist.Register.CNTL1, 0x01]), 0, 400e3)
        await spi_xfer("baro", bytes([baro.CMD_ADC_READ, 0, 0, 0]), 20e6)
        await spi_xfer("baro", bytes([(baro.CMD_CONVERT_D1, baro.CMD_CONVERT_D2)[frame % 2]]), 20e6)
    return log


class TlmChips:
    """:class:`Chips` over the transaction-level models, with their buses."""

    def __init__(self) -> None:
        self.imu, self.baro, self.mag = Mpu6000Model(), Ms5611Model(), Ist8310Model()
        self.spi = TlmSpiBus({"imu": self.imu, "baro": self.baro})
        self.i2c = TlmI2cBus({self.mag.address: self.mag})

    async def load(self, samples: dict[str, dict[str, int]], now_us: int) -> None:
        self.baro.now_us = self.mag.now_us = now_us
        if "imu" in samples:
            self.imu.load_sample(mpu.Mpu6000Sample(**samples["imu"]))
        if "baro" in samples:
            self.baro.load_sample(samples["baro"]["d1"], samples["baro"]["d2"])
        if "mag" in samples:
            x, y, z = (samples["mag"][axis] for axis in "xyz")
            self.mag.load_sample(ist.Ist8310Sample(x, y, z))


async def tlm_transcript() -> list[list[str]]:
    chips = TlmChips()
    return await run_script(chips.spi, chips.i2c, chips)


def tlm_transcript_now() -> list[list[str]]:
    """:func:`tlm_transcript` without an event loop (the TLM buses never suspend), so a
    cocotb test can compute it inside the simulator."""
    coroutine = tlm_transcript()
    try:
        coroutine.send(None)
    except StopIteration as done:
        return done.value
    raise AssertionError("a TLM bus suspended")
