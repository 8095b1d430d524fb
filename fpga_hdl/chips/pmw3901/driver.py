"""Autopilot-side PMW3901 driver: PX4's transfers and arithmetic, written once for any SpiBus.

It follows PX4's ``src/drivers/optical_flow/pmw3901/PMW3901.cpp`` (release 1.17):

- every register access is its own chip select at 2 MHz: a read is ``[reg, 0]``, a write
  ``[reg | 0x80, value]`` (PX4 then waits t_SWW);
- ``probe``: Product_ID must read 0x49;
- ``sensorInit``: the power-up reset, a 5 ms wait, one read each of Motion and the four
  Delta registers, a 1 ms wait, then the datasheet's performance-optimisation writes
  (``regs.OPTIMISATION_*``) with PX4's two branches on bank 0x0E's trim registers, and a
  10 ms wait before the last part. The waits go through the injected ``sleep_us``, as
  the MS5611 driver's do;
- ``RunImpl`` every 10 ms (:data:`SAMPLE_INTERVAL_US`): one 12-byte transfer reads Motion,
  the four Delta registers and SQUAL as address/data pairs; a delta beyond ±240 counts is
  taken for SPI garbage (quality 0); reads with quality > 0 are summed; once 15 ms
  (:data:`COLLECT_TIME_US`) have been integrated the sums are published as
  ``sensor_optical_flow`` (:class:`FlowReport`) and restart. Scheduling belongs to the
  caller, which owns simulated time: :meth:`Pmw3901Driver.cycle` takes ``now_us``.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass

import numpy as np

from fpga_hdl.buses.transactions import SpiBus
from fpga_hdl.chips.pmw3901 import regs
from fpga_hdl.chips.pmw3901.regs import Reg

__all__ = [
    "COLLECT_TIME_US",
    "COUNTS_PER_RAD",
    "SAMPLE_INTERVAL_US",
    "SPI_SPEED_HZ",
    "CameraCounts",
    "FlowReport",
    "Pmw3901Driver",
    "motion_read",
]

COUNTS_PER_RAD = 385.0  # PX4's conversion of the chip's counts to radians
SPI_SPEED_HZ = 2e6  # PX4 PMW3901_SPI_BUS_SPEED
SAMPLE_INTERVAL_US = 10_000  # PX4 PMW3901_SAMPLE_INTERVAL
COLLECT_TIME_US = 15_000  # PX4 _collect_time: publish every second cycle
#: PX4 ``readMotionCount``: a delta beyond this is SPI garbage.
GARBAGE_COUNTS = 240
#: PX4 sensorInit's waits: after the power-up reset, after the motion reads, before the
#: last optimisation writes.
RESET_WAIT_US, READ_WAIT_US, FINAL_WAIT_US = 5000, 1000, 10_000
#: PX4 ``TIME_us_TSWW``: after every write.
WRITE_WAIT_US = 11
#: PX4's one 12-byte motion read: Motion, Delta_X_L/H, Delta_Y_L/H, SQUAL as pairs.
MOTION_READ = bytes(
    byte for register in (Reg.MOTION, *regs.DELTA_REGISTERS, Reg.SQUAL) for byte in (register, 0)
)


@dataclass(frozen=True)
class FlowReport:  # PX4's sensor_optical_flow from the pmw3901 driver
    pixel_flow_rad: tuple[float, float]  # PX4's convention: + for a RH rotation about body x / y
    integration_timespan_us: int
    quality: int  # 0..255
    timestamp_us: int  # the read that closed the window


def motion_read(rx: bytes) -> tuple[int, int, int]:
    """PX4 ``readMotionCount``: (delta X, delta Y, quality) from the 12 bytes read, quality
    0 when a delta is beyond ±240 counts."""
    if len(rx) != len(MOTION_READ):
        raise ValueError(f"PMW3901 motion read is {len(MOTION_READ)} bytes, not {len(rx)}")
    delta_x = int.from_bytes(rx[3:6:2], "little", signed=True)
    delta_y = int.from_bytes(rx[7:10:2], "little", signed=True)
    garbage = max(abs(delta_x), abs(delta_y)) > GARBAGE_COUNTS
    return delta_x, delta_y, 0 if garbage else rx[11]


async def _no_wait(duration_us: int) -> None:
    """Start-up before simulated time begins: the chip is ready at once."""


class Pmw3901Driver:
    """PX4's PMW3901 sequence over any :class:`~fpga_hdl.buses.transactions.SpiBus`."""

    def __init__(
        self,
        bus: SpiBus,
        device: str = "flow",
        sleep_us: Callable[[int], Awaitable[None]] = _no_wait,
    ) -> None:
        self.bus = bus
        self.device = device
        self.sleep_us = sleep_us
        self._previous_us = 0
        self._dt_sum_us = 0
        self._sum_x = self._sum_y = 0
        self._quality_sum = 0
        self._count = 0

    async def read_register(self, register: int) -> int:
        """PX4 ``readRegister`` of one byte."""
        rx = await self.bus.transfer(self.device, bytes([register, 0]), sclk_hz=SPI_SPEED_HZ)
        return rx[1]

    async def write_register(self, register: int, value: int) -> None:
        """PX4 ``writeRegister``: the write, then t_SWW."""
        tx = bytes([register | regs.WRITE_FLAG, value])
        await self.bus.transfer(self.device, tx, sclk_hz=SPI_SPEED_HZ)
        await self.sleep_us(WRITE_WAIT_US)

    async def _write_all(self, writes: tuple[tuple[int, int], ...]) -> None:
        for register, value in writes:
            await self.write_register(register, value)

    async def probe(self) -> bool:
        """PX4 ``probe``: Product_ID reads 0x49."""
        return await self.read_register(Reg.PRODUCT_ID) == regs.PRODUCT_ID_VALUE

    async def init(self, now_us: int = 0) -> None:
        """PX4 ``sensorInit``, then the collect time starts at ``now_us`` (PX4 ``init``)."""
        await self.write_register(Reg.POWER_UP_RESET, regs.POWER_UP_RESET_VALUE)
        await self.sleep_us(RESET_WAIT_US)
        for register in (Reg.MOTION, *regs.DELTA_REGISTERS):
            await self.read_register(register)
        await self.sleep_us(READ_WAIT_US)
        await self._write_all(regs.OPTIMISATION_START)
        branch = await self.read_register(regs.TRIM_READ_REGISTER)
        await self.write_register(regs.TRIM_BRANCH_REGISTER, regs.TRIM_BRANCH_VALUES[branch >> 7])
        await self._write_all(regs.OPTIMISATION_MIDDLE)
        if await self.read_register(regs.TRIM_SKIP_REGISTER) == 0:
            c1 = await self.read_register(regs.TRIM_REGISTERS[0])
            c1 = min((c1 + (14 if c1 <= 28 else 11)) & 0xFF, 0x3F)  # unsigned char arithmetic
            c2 = await self.read_register(regs.TRIM_REGISTERS[1]) * 45 // 100
            await self._write_all(regs.OPTIMISATION_TRIM)
            await self._write_all(tuple(zip(regs.TRIM_REGISTERS, (c1, c2), strict=True)))
        await self._write_all(regs.OPTIMISATION_MAIN)
        await self.sleep_us(FINAL_WAIT_US)
        await self._write_all(regs.OPTIMISATION_FINAL)
        self._previous_us = now_us

    async def cycle(self, now_us: int) -> FlowReport | None:
        """PX4 ``RunImpl`` at ``now_us``: the motion read, and the report once the window
        has integrated :data:`COLLECT_TIME_US`."""
        self._dt_sum_us += now_us - self._previous_us
        self._previous_us = now_us
        rx = await self.bus.transfer(self.device, MOTION_READ, sclk_hz=SPI_SPEED_HZ)
        delta_x, delta_y, quality = motion_read(rx)
        if quality > 0:
            self._sum_x += delta_x
            self._sum_y += delta_y
            self._count = (self._count + 1) & 0xFF  # uint8_t
            self._quality_sum = (self._quality_sum + quality) & 0xFFFF  # uint16_t
        if self._dt_sum_us < COLLECT_TIME_US:
            return None
        report = FlowReport(
            pixel_flow_rad=(_radians(self._sum_x), _radians(self._sum_y)),
            integration_timespan_us=self._dt_sum_us,
            quality=self._quality_sum // self._count if self._count else 0,
            timestamp_us=now_us,
        )
        self._dt_sum_us = self._sum_x = self._sum_y = self._quality_sum = self._count = 0
        return report


class CameraCounts:
    """The camera's frames as the chip counts them, for the host to load.

    The chip reports whole counts of image motion (PX4 reads :data:`COUNTS_PER_RAD` of them
    to the radian) but tracks the motion finer inside, so the fraction left over from one
    frame is carried into the next and a long motion's counts never drift from it. The
    exposure becomes the shutter register: the longest exposure (a whole frame) at its
    top, ``2**SHUTTER_BITS - 1``.
    """

    def __init__(self) -> None:
        self._carry = np.zeros(2)

    def sample(self, flow_xy_rad: tuple[float, float], squal: int,
               exposure_frames: float) -> regs.Pmw3901Sample:  # fmt: skip
        """One frame's motion (rad about body x, y), SQUAL, and exposure (in frames)."""
        motion = self._carry + np.asarray(flow_xy_rad) * COUNTS_PER_RAD
        counts = np.round(motion)
        self._carry = motion - counts
        delta_x, delta_y = (int(np.clip(c, -32767, 32767)) for c in counts)  # int16 registers
        top = (1 << regs.SHUTTER_BITS) - 1
        shutter = min(max(round(exposure_frames * top), 0), top)
        return regs.Pmw3901Sample(delta_x, delta_y, min(max(squal, 0), 255), shutter)


def _radians(counts: int) -> float:
    """PX4's ``(float)sum / 385.0f``, in single precision as PX4 computes it."""
    return float(np.float32(counts) / np.float32(COUNTS_PER_RAD))
