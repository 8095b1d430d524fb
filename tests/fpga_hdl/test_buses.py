"""The transaction-level buses: routing, exact errors, and the bus contracts' arguments."""

import asyncio

import pytest

from fpga_hdl.buses.transactions import I2cNack, TlmI2cBus, TlmSpiBus, UnknownDevice


class Echo:
    """An SPI model that answers each byte with its complement (easy to check)."""

    def transfer(self, tx: bytes) -> bytes:
        return bytes(b ^ 0xFF for b in tx)


class Register:
    """An I2C model with a register pointer, as most sensors have."""

    def __init__(self) -> None:
        self.memory = bytes(range(16))

    def write_read(self, write: bytes, read_len: int) -> bytes:
        start = write[0] if write else 0
        return self.memory[start : start + read_len]


def test_spi_routes_by_chip_select():
    bus = TlmSpiBus({"imu": Echo()})
    assert asyncio.run(bus.transfer("imu", b"\x00\x0f", sclk_hz=1e6)) == b"\xff\xf0"


def test_spi_unknown_device_names_the_wired_ones():
    bus = TlmSpiBus({"imu": Echo(), "baro": Echo()})
    with pytest.raises(UnknownDevice, match=r"^no SPI device 'mag' on this bus; wired: baro, imu$"):
        asyncio.run(bus.transfer("mag", b"\x00", sclk_hz=1e6))


@pytest.mark.parametrize("sclk_hz", [0.0, -1.0, float("nan"), float("inf")])
def test_spi_rejects_impossible_clock(sclk_hz):
    bus = TlmSpiBus({"imu": Echo()})
    with pytest.raises(ValueError, match=r"^sclk_hz must be a positive finite frequency in Hz"):
        asyncio.run(bus.transfer("imu", b"\x00", sclk_hz=sclk_hz))


def test_i2c_write_then_read():
    bus = TlmI2cBus({0x0E: Register()})
    assert asyncio.run(bus.write_read(0x0E, b"\x03", 4, scl_hz=400e3)) == bytes([3, 4, 5, 6])


def test_i2c_wrong_address_is_a_nack():
    bus = TlmI2cBus({0x0E: Register()})
    with pytest.raises(I2cNack, match=r"^I2C target 0x0C did not acknowledge the address$") as info:
        asyncio.run(bus.write_read(0x0C, b"\x00", 1, scl_hz=400e3))
    assert (info.value.address, info.value.byte_index) == (0x0C, 0)


def test_i2c_rejects_10_bit_address():
    with pytest.raises(ValueError, match=r"^I2C address must be 7-bit \(0x00..0x7F\), not 0x80$"):
        TlmI2cBus({0x80: Register()})
