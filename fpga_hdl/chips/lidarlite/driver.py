"""Autopilot-side LIDAR-Lite driver: PX4's transactions and decoding, written once for any I2cBus.

It issues the transfers of PX4's ``src/drivers/distance_sensor/ll40ls/LidarLiteI2C.cpp``
for a v1/v2/v3 part. Every register read there is ``lidar_transfer``: the pointer written
in one transfer (ending with a STOP), the data read in a second one, never a repeated
START. Register writes are one transfer of pointer and value. The sequences:

- probe: HW_VERSION, SW_VERSION, UNIT_ID_HIGH, UNIT_ID_LOW, then the version from them;
- reset (``reset_sensor``): SIG_COUNT_VAL = 0xFF, ACQ_COMMAND = reset, SIG_COUNT_VAL =
  0xFF again (PX4 sleeps 15, 15 and 50 ms between them);
- measure: ACQ_COMMAND = 0x04;
- collect: two bytes from ``FULL_DELAY_HIGH | 0x80`` (auto-increment), then
  SIGNAL_STRENGTH and PEAK_CORR one byte each.

PX4 v1.14 first tries a LIDAR-Lite v4's identification registers (their addresses are in
a header this project could not read); a v3 answers 0 there, which PX4 takes as "not a
v4", so that step changes nothing for this chip and is not issued.

Scheduling (collect then measure every 50 ms, :data:`PX4_CYCLE_US`) belongs to the
caller, which owns simulated time.
"""

from dataclasses import dataclass
from enum import Enum

from fpga_hdl.buses.transactions import I2cBus
from fpga_hdl.chips.lidarlite import regs
from fpga_hdl.chips.lidarlite.regs import LidarLiteSample, Register

__all__ = [
    "PX4_CYCLE_US",
    "LidarLiteDriver",
    "LidarLiteVersion",
    "Range",
    "decode_range",
    "sample_from_range",
]

#: PX4 ``I2C_SPEED`` of the ll40ls driver: Fast-mode.
PX4_SCL_HZ = 400e3
#: PX4 ``LL40LS_CONVERSION_INTERVAL``: each run collects the last measurement and starts
#: the next, 50 ms apart (20 Hz).
PX4_CYCLE_US = 50_000
#: PX4 ``LL40LS_SIG_COUNT_VAL_MAX``, written by ``reset_sensor``.
SIG_COUNT_MAX = 0xFF
#: PX4 ``LL40LS_MAX_DISTANCE`` (v1/v3) and ``LL40LS_MAX_DISTANCE_V2``.
PX4_MAX_DISTANCE_M = 25.0
PX4_MAX_DISTANCE_V2_M = 35.0
#: Strengths the rig loads with a valid return: the relative strength well above PX4's
#: 24 and the peak at PX4's top of scale, which PX4 rates 100 % quality.
VALID_SIGNAL_STRENGTH = 128
VALID_PEAK_STRENGTH = regs.PEAK_STRENGTH_HIGH


class LidarLiteVersion(Enum):
    """What PX4's probe concludes from the ID registers."""

    V1_V3 = "v1/v3"
    V2 = "v2"
    V3HP = "v3HP"


@dataclass(frozen=True)
class Range:
    """One collected measurement as PX4 publishes it (``distance_sensor``)."""

    distance_m: float
    #: 0..100 %; 0 marks a reading the estimator must not use.
    signal_quality: int


def sample_from_range(distance_m: float | None) -> LidarLiteSample:
    """The chip's registers for a measured distance (cm, rounded); ``None`` is no return."""
    if distance_m is None:
        return LidarLiteSample(regs.NO_RETURN_CM, 0, 0)
    distance_cm = min(max(round(distance_m * 100), 0), 0x7FFF)
    return LidarLiteSample(distance_cm, VALID_SIGNAL_STRENGTH, VALID_PEAK_STRENGTH)


def decode_range(distance: bytes, signal_strength: int, peak_strength: int) -> Range | None:
    """PX4's ``collect`` for a v1/v2/v3: ``None`` when the high bit marks the distance
    invalid; below 5 cm or with a weak signal the quality is 0."""
    if len(distance) != 2:
        raise ValueError(f"LIDAR-Lite distance read must be 2 bytes, not {len(distance)}")
    if distance[0] & 0x80:
        return None
    distance_m = int.from_bytes(distance, "big") * 1e-2
    if signal_strength <= regs.SIGNAL_STRENGTH_LOW or distance_m < regs.MIN_RANGE_M:
        return Range(distance_m, 0)
    span = regs.PEAK_STRENGTH_HIGH - regs.PEAK_STRENGTH_LOW
    quality = 100 * max(peak_strength - regs.PEAK_STRENGTH_LOW, 0) // span
    return Range(distance_m, quality)


class LidarLiteDriver:
    """PX4's LIDAR-Lite sequence over any :class:`~fpga_hdl.buses.transactions.I2cBus`."""

    def __init__(
        self, bus: I2cBus, *, address: int = regs.DEFAULT_ADDRESS, scl_hz: float = PX4_SCL_HZ
    ) -> None:
        self.bus = bus
        self.address = address
        self.scl_hz = scl_hz
        self.version: LidarLiteVersion | None = None

    async def read_register(self, pointer: int, length: int = 1) -> bytes:
        """PX4 ``lidar_transfer``: the pointer in one transfer, the data in the next."""
        await self.bus.write_read(self.address, bytes([pointer]), 0, scl_hz=self.scl_hz)
        return await self.bus.write_read(self.address, b"", length, scl_hz=self.scl_hz)

    async def write_register(self, register: Register, value: int) -> None:
        """PX4 ``write_reg``: pointer and value in one write."""
        await self.bus.write_read(self.address, bytes([register, value]), 0, scl_hz=self.scl_hz)

    async def probe(self) -> LidarLiteVersion | None:
        """PX4 ``probe``: the version from HW_VERSION and UNIT_ID; ``None`` for none PX4
        accepts (HW_VERSION and UNIT_ID both 0)."""
        (hw_version,) = await self.read_register(Register.HW_VERSION)
        await self.read_register(Register.SW_VERSION)
        (id_high,) = await self.read_register(Register.UNIT_ID_HIGH)
        (id_low,) = await self.read_register(Register.UNIT_ID_LOW)
        unit_id = id_high << 8 | id_low
        if hw_version > 0:
            self.version = LidarLiteVersion.V2 if unit_id else LidarLiteVersion.V1_V3
        elif unit_id:
            self.version = LidarLiteVersion.V3HP
        else:
            self.version = None
        return self.version

    @property
    def max_distance_m(self) -> float:
        """The limit PX4 publishes for the probed version."""
        return PX4_MAX_DISTANCE_V2_M if self.version is LidarLiteVersion.V2 else PX4_MAX_DISTANCE_M

    async def reset(self) -> None:
        """PX4 ``reset_sensor`` (its sleeps belong to the caller)."""
        await self.write_register(Register.SIG_COUNT_VAL, SIG_COUNT_MAX)
        await self.write_register(Register.ACQ_COMMAND, regs.ACQ_RESET)
        await self.write_register(Register.SIG_COUNT_VAL, SIG_COUNT_MAX)

    async def measure(self) -> None:
        """PX4 ``measure``: start one acquisition."""
        await self.write_register(Register.ACQ_COMMAND, regs.ACQ_MEASURE)

    async def collect(self) -> Range | None:
        """PX4 ``collect``: distance (auto-increment read), signal and peak strength."""
        distance = await self.read_register(
            Register.FULL_DELAY_HIGH | regs.POINTER_AUTO_INCREMENT, 2
        )
        if distance[0] & 0x80:
            return None
        (signal_strength,) = await self.read_register(Register.SIGNAL_STRENGTH)
        (peak_strength,) = await self.read_register(Register.PEAK_CORR)
        return decode_range(distance, signal_strength, peak_strength)
