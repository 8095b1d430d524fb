"""Autopilot-side IST8310 driver: PX4's transactions and decoding, written once for any I2cBus.

It issues exactly the transfers of PX4's ``src/drivers/magnetometer/isentek/ist8310/
IST8310.cpp``: a WAI probe, CNTL2 soft reset, the four checked configuration registers
(read, set/clear bits, write only when different, read back), CNTL1 single measurement,
and one 7-byte read from STAT1 (DRDY, then X/Y/Z little-endian) with a repeated START.
Scheduling (PX4 waits 50 ms after reset and 20 ms per measurement) belongs to the caller,
which owns simulated time.

Axes: PX4 reads the chip as +x forward, +y right, +z up and negates z
(``z = (z == INT16_MIN) ? INT16_MAX : -z``) before the board rotation, so its sensor
frame is forward-right-down. :func:`decode_field_gauss` returns that frame and
:func:`sample_from_field_gauss` is its inverse for the rig; the board rotation
(``ROTATION_NONE`` by default) is not emulated.
"""

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fpga_hdl.buses.transactions import I2cBus
from fpga_hdl.chips.ist8310 import regs
from fpga_hdl.chips.ist8310.regs import Ist8310Sample, Register

__all__ = [
    "PX4_REGISTER_CONFIG",
    "Ist8310Driver",
    "RegisterConfig",
    "decode_field_gauss",
    "sample_from_field_gauss",
]

#: PX4 ``iSentek_IST8310::I2C_SPEED``: Fast-mode.
PX4_SCL_HZ = 400e3
#: Bytes of PX4's measurement read: STAT1 then DATAXL..DATAZH.
MEASUREMENT_READ_LEN = 7

_INT16_MIN, _INT16_MAX = -32768, 32767


@dataclass(frozen=True)
class RegisterConfig:
    """A register PX4 configures and periodically checks."""

    register: Register
    set_bits: int
    clear_bits: int

    def holds(self, value: int) -> bool:
        """True when ``value`` has every set bit set and every clear bit clear."""
        return value & self.set_bits == self.set_bits and value & self.clear_bits == 0


#: PX4 ``IST8310::_register_cfg``, in PX4's order.
PX4_REGISTER_CONFIG = (
    RegisterConfig(Register.CNTL2, 0, regs.CNTL2_SRST),
    RegisterConfig(Register.CNTL3, regs.CNTL3_X_16BIT | regs.CNTL3_Y_16BIT | regs.CNTL3_Z_16BIT, 0),
    RegisterConfig(Register.AVGCNTL, regs.AVGCNTL_16X, 0),
    RegisterConfig(Register.PDCNTL, regs.PDCNTL_NORMAL, 0),
)


def decode_field_gauss(measurement: bytes) -> tuple[float, float, float] | None:
    """PX4's decoding of the 7-byte STAT1..DATAZH read; ``None`` when DRDY is clear."""
    if len(measurement) != MEASUREMENT_READ_LEN:
        raise ValueError(
            f"IST8310 measurement must be {MEASUREMENT_READ_LEN} bytes, not {len(measurement)}"
        )
    if not measurement[0] & regs.STAT1_DRDY:
        return None
    x, y, z = (int.from_bytes(measurement[i : i + 2], "little", signed=True) for i in (1, 3, 5))
    z = _INT16_MAX if z == _INT16_MIN else -z
    scale = 1.0 / regs.LSB_PER_GAUSS_16BIT
    return x * scale, y * scale, z * scale


def sample_from_field_gauss(field_frd_gauss: ArrayLike) -> Ist8310Sample:
    """Chip counts (16-bit mode) for a field in PX4's sensor frame; saturates at int16."""
    # As Python floats: arithmetic on numpy's scalars costs several times more, and the
    # rig converts every mag sample.
    field = np.asarray(field_frd_gauss, dtype=np.float64).ravel().tolist()
    if len(field) != 3:
        raise ValueError(f"field must have 3 components (x, y, z), not {len(field)}")
    x, y, z_down = (round(value * regs.LSB_PER_GAUSS_16BIT) for value in field)
    return Ist8310Sample(*(min(max(c, _INT16_MIN), _INT16_MAX) for c in (x, y, -z_down)))


class Ist8310Driver:
    """PX4's IST8310 transaction sequence over any :class:`~fpga_hdl.buses.transactions.I2cBus`."""

    def __init__(
        self, bus: I2cBus, *, address: int = regs.DEFAULT_ADDRESS, scl_hz: float = PX4_SCL_HZ
    ) -> None:
        self.bus = bus
        self.address = address
        self.scl_hz = scl_hz
        self._checked = 0

    async def read_register(self, register: Register) -> int:
        """PX4 ``RegisterRead``: write the pointer, repeated START, read one byte."""
        (value,) = await self.bus.write_read(self.address, bytes([register]), 1, scl_hz=self.scl_hz)
        return value

    async def write_register(self, register: Register, value: int) -> None:
        """PX4 ``RegisterWrite``: pointer and value in one write."""
        await self.bus.write_read(self.address, bytes([register, value]), 0, scl_hz=self.scl_hz)

    async def probe(self) -> bool:
        """PX4 ``probe``: WAI must read the device ID."""
        return await self.read_register(Register.WAI) == regs.DEVICE_ID

    async def reset(self) -> None:
        """PX4 state RESET: CNTL2 soft reset (then PX4 waits 50 ms)."""
        await self.write_register(Register.CNTL2, regs.CNTL2_SRST)

    async def reset_done(self) -> bool:
        """PX4 state WAIT_FOR_RESET: WAI reads the ID and CNTL2.SRST has cleared."""
        if await self.read_register(Register.WAI) != regs.DEVICE_ID:
            return False
        return not await self.read_register(Register.CNTL2) & regs.CNTL2_SRST

    async def configure(self) -> bool:
        """PX4 ``Configure``: set/clear each register's bits, then check them all."""
        for config in PX4_REGISTER_CONFIG:
            value = await self.read_register(config.register)
            wanted = value & ~config.clear_bits | config.set_bits
            if wanted != value:
                await self.write_register(config.register, wanted)
        results = [await self.check_register(config) for config in PX4_REGISTER_CONFIG]
        return all(results)

    async def check_register(self, config: RegisterConfig) -> bool:
        """PX4 ``RegisterCheck``."""
        return config.holds(await self.read_register(config.register))

    async def check_next_register(self) -> bool:
        """PX4's periodic check: one configured register per call, round robin."""
        ok = await self.check_register(PX4_REGISTER_CONFIG[self._checked])
        if ok:
            self._checked = (self._checked + 1) % len(PX4_REGISTER_CONFIG)
        return ok

    async def start_measurement(self) -> None:
        """PX4 state MEASURE: CNTL1 single measurement."""
        await self.write_register(Register.CNTL1, regs.CNTL1_MODE_SINGLE)

    async def read_measurement(self) -> bytes:
        """PX4 state READ: 7 bytes from STAT1 in one combined transfer."""
        return await self.bus.write_read(
            self.address, bytes([Register.STAT1]), MEASUREMENT_READ_LEN, scl_hz=self.scl_hz
        )

    async def read_field_gauss(self) -> tuple[float, float, float] | None:
        """Read and decode one measurement; ``None`` while data is not ready."""
        return decode_field_gauss(await self.read_measurement())
