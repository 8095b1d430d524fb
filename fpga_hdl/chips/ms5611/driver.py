"""Autopilot-side MS5611 driver: PX4's SPI transactions, compensated to SI units.

Transactions follow PX4's ``src/drivers/barometer/ms5611/ms5611_spi.cpp`` and
``ms5611.cpp``: SPI mode 3 at 20 MHz; RESET is a 1-byte transfer of 0x1E, then a 3 ms
wait; each PROM word is a 3-byte transfer (command, two data bytes) and the PROM must
pass the CRC4 and must not be all zeros; a conversion is a 1-byte CONVERT command
(OSR 1024: 0x44 pressure, 0x54 temperature); after PX4's 10 ms conversion interval, a
4-byte transfer with command 0x00 reads the 24-bit result. Time passes through the
injected ``sleep_us`` coroutine, as PX4's ``ScheduleDelayed`` lets it pass.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from fpga_hdl.buses.transactions import BusError, SpiBus
from fpga_hdl.chips.ms5611 import regs

SPI_SPEED_HZ = 20e6  # PX4 MS5611_SPI: 20 MHz, mode 3
RESET_WAIT_US = 3000  # PX4 _read_prom(): "wait for PROM contents ... (2.8 ms)"
CONVERSION_INTERVAL_US = 10000  # PX4 MS5611_CONVERSION_INTERVAL
PX4_OSR = regs.Osr.OSR_1024  # PX4 ADDR_CMD_CONVERT_D1/D2 = *_OSR1024


class Ms5611Error(BusError):
    """The chip answered, but its PROM or its results are not usable."""


@dataclass(frozen=True)
class BaroReading:
    pressure_pa: float
    temperature_c: float
    d1: int
    d2: int


class Ms5611Driver:
    """PX4's MS5611 sequence over any :class:`SpiBus`."""

    def __init__(
        self,
        bus: SpiBus,
        sleep_us: Callable[[int], Awaitable[None]],
        device: str = "baro",
        osr: regs.Osr = PX4_OSR,
    ) -> None:
        self.bus = bus
        self.sleep_us = sleep_us
        self.device = device
        self.osr = osr
        self.prom: tuple[int, ...] = ()

    async def _transfer(self, tx: bytes) -> bytes:
        return await self.bus.transfer(self.device, tx, sclk_hz=SPI_SPEED_HZ)

    async def reset(self) -> None:
        await self._transfer(bytes([regs.CMD_RESET]))

    async def read_prom(self) -> tuple[int, ...]:
        words = []
        for index in range(8):
            rx = await self._transfer(bytes([regs.CMD_PROM_READ + 2 * index, 0, 0]))
            words.append(int.from_bytes(rx[1:3], "big"))
        prom = tuple(words)
        if not any(prom):
            raise Ms5611Error("MS5611 PROM reads all zeros")
        if regs.crc4(prom) != prom[7] & 0xF:
            raise Ms5611Error(
                f"MS5611 PROM CRC4 mismatch: computed 0x{regs.crc4(prom):X}, "
                f"word 7 holds 0x{prom[7] & 0xF:X}"
            )
        return prom

    async def start(self) -> None:
        await self.reset()
        await self.sleep_us(RESET_WAIT_US)
        self.prom = await self.read_prom()

    async def convert(self, command: int) -> None:
        await self._transfer(bytes([command + self.osr]))

    async def read_adc(self) -> int:
        rx = await self._transfer(bytes([regs.CMD_ADC_READ, 0, 0, 0]))
        return int.from_bytes(rx[1:4], "big")

    async def measure(self) -> BaroReading:
        """Temperature conversion, then pressure, each read after PX4's interval."""
        if not self.prom:
            raise Ms5611Error("MS5611 driver not started: call start() to read the PROM")
        await self.convert(regs.CMD_CONVERT_D2)
        await self.sleep_us(CONVERSION_INTERVAL_US)
        d2 = await self.read_adc()
        await self.convert(regs.CMD_CONVERT_D1)
        await self.sleep_us(CONVERSION_INTERVAL_US)
        d1 = await self.read_adc()
        if d1 == 0 or d2 == 0:  # PX4 ms5611.cpp: a zero result means a read too early
            raise Ms5611Error(f"MS5611 conversion not ready: D1={d1}, D2={d2}")
        result = regs.compensate(d1, d2, self.prom)
        return BaroReading(result.pressure_pa, result.temperature_c, d1, d2)
