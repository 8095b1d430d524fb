"""TE MS5611-01BA03 commands, PROM, conversion times and compensation formulas.

Source: MS5611-01BA03 datasheet (TE Connectivity / MEAS, rev. 09/2015): "Commands"
(RESET 0x1E, CONVERT D1 0x40..0x48, CONVERT D2 0x50..0x58, ADC READ 0x00, PROM READ
0xA0..0xAE), the conversion-time table (maximum values used, so a driver that waits
what the datasheet says always finds its result ready), "Pressure and temperature
calculation" (first order) and "Second order temperature compensation"; the PROM CRC4 is
Application Note AN520. PX4's ``src/drivers/barometer/ms5611/`` uses the same commands,
OSR 1024, SPI mode 3 and 20 MHz.

Defined once here and imported by the gateware, the model, the driver and the tests.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from amaranth.hdl import unsigned
from amaranth.lib import data

CMD_RESET = 0x1E
CMD_ADC_READ = 0x00
CMD_CONVERT_D1 = 0x40
CMD_CONVERT_D2 = 0x50
CMD_PROM_READ = 0xA0
#: The MS5611 supports SPI up to 20 MHz (datasheet, "Specifications").
SCLK_MAX_HZ = 20e6


class Osr(IntEnum):
    """Oversampling ratio; its value is the command offset (0x40 + value = D1 at that OSR)."""

    OSR_256 = 0x0
    OSR_512 = 0x2
    OSR_1024 = 0x4
    OSR_2048 = 0x6
    OSR_4096 = 0x8


#: Maximum ADC conversion time per OSR in microseconds (datasheet "Operating conditions").
CONVERSION_TIME_US: dict[int, int] = {  # by command offset: an Osr is its int
    Osr.OSR_256: 600,
    Osr.OSR_512: 1170,
    Osr.OSR_1024: 2280,
    Osr.OSR_2048: 4540,
    Osr.OSR_4096: 9040,
}

#: D1 (pressure) and D2 (temperature), unsigned 24-bit ADC results.
SAMPLE_LAYOUT = data.StructLayout({"d1": unsigned(24), "d2": unsigned(24)})

#: The datasheet's example/typical coefficients C1..C6 ("Pressure and temperature
#: calculation" table); word 0 (factory data, no value given) is an arbitrary constant.
DATASHEET_COEFFICIENTS = (40127, 36924, 23317, 23282, 33464, 28312)
FACTORY_WORD = 0x0A5C
SERIAL_WORD_HIGH = 0x4F2  # word 7 bits 15..4: serial code, arbitrary


def crc4(prom: tuple[int, ...]) -> int:
    """AN520 CRC4 over the 8 PROM words, with word 7's low nibble (the CRC) taken as 0.

    Written by hand because it is a 4-bit CRC defined only by this application note.
    """
    if len(prom) != 8:
        raise ValueError(f"the MS5611 PROM has 8 words, not {len(prom)}")
    words = [*prom[:7], prom[7] & 0xFF00]
    remainder = 0
    for count in range(16):
        word = words[count >> 1]
        remainder ^= (word & 0x00FF) if count % 2 else (word >> 8)
        for _ in range(8):
            remainder = ((remainder << 1) ^ 0x3000) if remainder & 0x8000 else remainder << 1
            remainder &= 0xFFFF
    return (remainder >> 12) & 0xF


def make_prom(
    coefficients: tuple[int, ...], *, factory_word: int = FACTORY_WORD
) -> tuple[int, ...]:
    """The 8 PROM words for C1..C6, with a valid CRC4 in word 7's low nibble."""
    if len(coefficients) != 6 or not all(0 <= c <= 0xFFFF for c in coefficients):
        raise ValueError(f"need six 16-bit coefficients C1..C6, not {coefficients!r}")
    words = (factory_word, *coefficients, SERIAL_WORD_HIGH << 4)
    return (*words[:7], words[7] | crc4(words))


DEFAULT_PROM = make_prom(DATASHEET_COEFFICIENTS)


@dataclass(frozen=True)
class Compensated:
    """The datasheet's integer results: TEMP in 0.01 °C, P in 0.01 mbar (= Pa)."""

    dt: int
    temp: int
    off: int
    sens: int
    pressure: int

    @property
    def temperature_c(self) -> float:
        return self.temp / 100.0

    @property
    def pressure_pa(self) -> float:
        return float(self.pressure)


def compensate(
    d1: int, d2: int, prom: tuple[int, ...], *, second_order: bool = True
) -> Compensated:
    """The datasheet's calculation, integer arithmetic with floor shifts as PX4 does."""
    c1, c2, c3, c4, c5, c6 = prom[1:7]
    dt = d2 - (c5 << 8)
    temp = 2000 + ((dt * c6) >> 23)
    off = (c2 << 16) + ((c4 * dt) >> 7)
    sens = (c1 << 15) + ((c3 * dt) >> 8)
    if second_order and temp < 2000:
        t2 = (dt * dt) >> 31
        off2 = 5 * (temp - 2000) ** 2 >> 1
        sens2 = 5 * (temp - 2000) ** 2 >> 2
        if temp < -1500:
            off2 += 7 * (temp + 1500) ** 2
            sens2 += 11 * (temp + 1500) ** 2 >> 1
        temp, off, sens = temp - t2, off - off2, sens - sens2
    pressure = (((d1 * sens) >> 21) - off) >> 15
    return Compensated(dt=dt, temp=temp, off=off, sens=sens, pressure=pressure)
