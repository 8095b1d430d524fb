"""The transaction-level buses: routing, exact errors, and the bus contracts' arguments."""

import asyncio

import pytest

from fpga_hdl.buses.transactions import (
    I2cNack,
    TlmI2cBus,
    TlmSpiBus,
    UnknownDevice,
    check_i2c_request,
    check_spi_mode,
    check_spi_request,
    combined_transfer,
)


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


# --- the one request validator every bus runs ---------------------------------------------

I2C_REQUEST_ERRORS = [
    ((0x80, b"", 1), {}, r"I2C address must be 7-bit \(0x00..0x7F\), not 0x80"),
    ((0x0E, b"\x00", -1), {}, r"read_len must be >= 0, not -1"),
    ((0x0E, b"\x00", 17), {"read_depth": 16}, r"read_len must be in 0..16, not 17"),
    ((0x0E, bytes(9), 0), {"write_depth": 8}, r"I2C write of 9 bytes exceeds 8"),
]


@pytest.mark.parametrize(("request_", "depths", "message"), I2C_REQUEST_ERRORS)
def test_i2c_request_errors_are_one_line(request_, depths, message):
    with pytest.raises(ValueError, match=rf"^{message}$"):
        check_i2c_request(*request_, **depths)


def test_i2c_request_within_the_depths_passes():
    check_i2c_request(0x7F, bytes(8), 16, write_depth=8, read_depth=16)


def test_tlm_i2c_bus_runs_the_shared_validator():
    bus = TlmI2cBus({0x0E: Register()})
    with pytest.raises(ValueError, match=r"^read_len must be >= 0, not -1$"):
        asyncio.run(bus.write_read(0x0E, b"\x00", -1, scl_hz=400e3))


class Recorder:
    """An :class:`I2cByteController` that records the bus conditions it is asked for."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    async def start(self) -> None:
        self.calls.append("start")

    async def stop(self) -> None:
        self.calls.append("stop")

    async def write_byte(self, byte: int) -> bool:
        self.calls.append(f"w{byte:02x}")
        return True

    async def read_byte(self, *, ack: bool) -> int:
        self.calls.append("r")
        return 0


def test_pin_level_sequence_is_refused_before_its_first_condition():
    """The pin-level masters share combined_transfer: a bad request drives no edge."""
    controller = Recorder()
    with pytest.raises(ValueError, match=r"^I2C address must be 7-bit"):
        asyncio.run(combined_transfer(controller, 0x80, b"\x00", 1))
    assert controller.calls == []
    asyncio.run(combined_transfer(controller, 0x0E, b"\x03", 1))
    assert controller.calls == ["start", "w1c", "w03", "start", "w1d", "r", "stop"]


def test_spi_request_errors_are_one_line():
    with pytest.raises(UnknownDevice, match=r"^no SPI device 'gps' on this bus; wired: baro, imu$"):
        check_spi_request("gps", b"\x00", ("imu", "baro"))
    with pytest.raises(ValueError, match=r"^SPI transfer of 17 bytes exceeds the 16-byte buffer$"):
        check_spi_request("imu", bytes(17), ("imu", "baro"), depth=16)
    check_spi_request("imu", bytes(16), ("imu", "baro"), depth=16)


@pytest.mark.parametrize("mode", [1, 2, "0"])
def test_spi_modes_other_than_0_and_3_are_refused(mode):
    with pytest.raises(ValueError, match=r"^SPI mode must be 0 or 3 \(the chips' modes\), not "):
        check_spi_mode(mode)
