"""Bus protocols shared by every autopilot-side driver, and their transaction-level buses.

A driver (``mpu6000.driver``, ``ms5611.driver``, ``ist8310.driver``) is written once
against :class:`SpiBus` or :class:`I2cBus`, the way Glasgow applets are written against
an interface. Two kinds of bus implement each protocol:

- the pin-level bus masters in ``fpga_hdl.verification`` drive the generated Verilog under
  cocotb (real SCLK/SCL edges, real timing);
- the transaction-level buses here call the pure-Python chip models directly, so a
  campaign can run the same register maps without a simulator.

Because both run the very same driver code, a test can compare the bytes they return.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Protocol, runtime_checkable


class BusError(Exception):
    """Base class of bus failures a driver may see (a misaddressed or silent chip)."""


class I2cNack(BusError):
    """The target did not acknowledge: wrong address, muted chip, or a refused byte.

    ``byte_index`` is 0 for the address byte, 1.. for the written data bytes.
    """

    def __init__(self, address: int, byte_index: int = 0) -> None:
        self.address = address
        self.byte_index = byte_index
        what = "address" if byte_index == 0 else f"write byte {byte_index}"
        super().__init__(f"I2C target 0x{address:02X} did not acknowledge the {what}")


class UnknownDevice(BusError):
    """An SPI transfer named a chip select that is not wired on this bus."""


class SpiBus(Protocol):
    """Full-duplex SPI: chip select asserted around ``tx``, the same number of bytes back."""

    async def transfer(self, device: str, tx: bytes, *, sclk_hz: float) -> bytes: ...


class I2cBus(Protocol):
    """I2C combined transfer: write ``write`` (may be empty), then read ``read_len`` bytes.

    A write followed by a read uses a repeated START between them, as PX4's
    ``I2C::transfer`` does. Raises :class:`I2cNack` when the target does not acknowledge.
    """

    async def write_read(
        self, address: int, write: bytes, read_len: int, *, scl_hz: float
    ) -> bytes: ...


@dataclass(frozen=True)
class UartTransfer:
    """What one UART exchange brought back from the receiver."""

    data: bytes
    #: From the first start bit's falling edge to the strobe of the last byte in the
    #: autopilot's UART, in µs rounded up (``fpga_hdl.buses.uart.line_cycles``); 0 when
    #: nothing arrived.
    line_us: int


class UartPort(Protocol):
    """The autopilot's UART to a receiver (8N1): send ``tx`` at ``baud``, then everything
    the receiver sends until its line rests (it answers at once, or not at all)."""

    async def exchange(self, tx: bytes, *, baud: int) -> UartTransfer: ...


class I2cByteController(Protocol):
    """A bit-level I2C controller: bus conditions and whole bytes with their acknowledge bit.

    The pin-level master under cocotb and the amaranth.sim test controller implement it
    over their own primitives and share :func:`combined_transfer` for the sequence.
    """

    async def start(self) -> None: ...  # START, or repeated START while SCL is held low

    async def stop(self) -> None: ...

    async def write_byte(self, byte: int) -> bool: ...  # True when the target ACKs

    async def read_byte(self, *, ack: bool) -> int: ...  # then ACK (``ack``) or NACK it


async def combined_transfer(
    controller: I2cByteController, address: int, write: bytes, read_len: int
) -> bytes:
    """One :meth:`I2cBus.write_read` as bus conditions (UM10204 rev. 7, 3.1.10, combined format).

    START, address+W, the ``write`` bytes, repeated START, address+R, ``read_len`` bytes
    ACKed but the last, which is NACKed, then STOP. An empty ``write`` skips the write
    part; an empty transfer is an address probe. A NACK ends the transfer with a STOP and
    raises :class:`I2cNack`, as PX4's ``I2C::transfer`` reports it.
    """
    check_i2c_request(address, write, read_len)
    await controller.start()
    if write or not read_len:
        if not await controller.write_byte(address << 1):
            await controller.stop()
            raise I2cNack(address)
        for index, byte in enumerate(write, start=1):
            if not await controller.write_byte(byte):
                await controller.stop()
                raise I2cNack(address, index)
        if read_len:
            await controller.start()
    data = bytearray()
    if read_len:
        if not await controller.write_byte(address << 1 | 1):
            await controller.stop()
            raise I2cNack(address)
        for index in range(read_len):
            data.append(await controller.read_byte(ack=index < read_len - 1))
    await controller.stop()
    return bytes(data)


@runtime_checkable
class SpiDeviceModel(Protocol):
    """A transaction-level SPI chip: one call per chip-select assertion."""

    def transfer(self, tx: bytes) -> bytes: ...


@runtime_checkable
class I2cDeviceModel(Protocol):
    """A transaction-level I2C chip; raises :class:`I2cNack` for a refused data byte."""

    def write_read(self, write: bytes, read_len: int) -> bytes: ...


def check_clock_hz(name: str, value_hz: float) -> None:
    """Reject a bus clock that no real master could produce (zero, negative, NaN, inf)."""
    if not (math.isfinite(value_hz) and value_hz > 0):
        raise ValueError(f"{name} must be a positive finite frequency in Hz, not {value_hz!r}")


# The request checks every bus runs before its first edge, written once so a driver's
# mistake reads the same one-line error on the TLM, the pin-level masters, the harness
# and the compiled harness. ``depth`` arguments are a bus's buffer sizes (None: unbounded).


def check_spi_mode(mode: int) -> None:
    """Reject an SPI mode the chips do not speak (both take modes 0 and 3 only)."""
    if mode not in (0, 3):
        raise ValueError(f"SPI mode must be 0 or 3 (the chips' modes), not {mode!r}")


def check_spi_request(
    device: str, tx: bytes, wired: Collection[str], *, depth: int | None = None
) -> None:
    """Reject a transfer to a chip select not in ``wired`` or longer than ``depth`` bytes."""
    if device not in wired:
        raise UnknownDevice(
            f"no SPI device {device!r} on this bus; wired: {', '.join(sorted(wired))}"
        )
    if depth is not None and len(tx) > depth:
        raise ValueError(f"SPI transfer of {len(tx)} bytes exceeds the {depth}-byte buffer")


def check_i2c_address(address: int) -> None:
    """Reject an address that does not fit the 7 bits before the R/W bit."""
    if not 0 <= address <= 0x7F:
        raise ValueError(f"I2C address must be 7-bit (0x00..0x7F), not 0x{address:X}")


def check_i2c_request(
    address: int,
    write: bytes,
    read_len: int,
    *,
    write_depth: int | None = None,
    read_depth: int | None = None,
) -> None:
    """Reject a combined transfer no bus could carry: bad address, read or write length."""
    check_i2c_address(address)
    if read_len < 0 or (read_depth is not None and read_len > read_depth):
        bound = ">= 0" if read_depth is None else f"in 0..{read_depth}"
        raise ValueError(f"read_len must be {bound}, not {read_len}")
    if write_depth is not None and len(write) > write_depth:
        raise ValueError(f"I2C write of {len(write)} bytes exceeds {write_depth}")


class TlmSpiBus:
    """:class:`SpiBus` over pure-Python chip models, keyed by chip-select name."""

    def __init__(self, devices: Mapping[str, SpiDeviceModel]) -> None:
        self.devices = dict(devices)

    async def transfer(self, device: str, tx: bytes, *, sclk_hz: float) -> bytes:
        check_clock_hz("sclk_hz", sclk_hz)
        check_spi_request(device, tx, self.devices)
        rx = self.devices[device].transfer(bytes(tx))
        if len(rx) != len(tx):
            raise BusError(f"SPI model {device!r} returned {len(rx)} bytes for {len(tx)} sent")
        return rx


class TlmI2cBus:
    """:class:`I2cBus` over pure-Python chip models, keyed by 7-bit address."""

    def __init__(self, devices: Mapping[int, I2cDeviceModel]) -> None:
        for address in devices:
            check_i2c_address(address)
        self.devices = dict(devices)

    async def write_read(
        self, address: int, write: bytes, read_len: int, *, scl_hz: float
    ) -> bytes:
        check_clock_hz("scl_hz", scl_hz)
        check_i2c_request(address, write, read_len)
        model = self.devices.get(address)
        if model is None:
            raise I2cNack(address)
        rx = model.write_read(bytes(write), read_len)
        if len(rx) != read_len:
            raise BusError(
                f"I2C model 0x{address:02X} returned {len(rx)} bytes for {read_len} requested"
            )
        return rx
