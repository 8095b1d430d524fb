"""Autopilot-side MPU-6000 driver: PX4's SPI transactions, decoded to SI units.

Transactions follow PX4's ``src/drivers/imu/invensense/mpu6000/MPU6000.cpp``: every
register access is a 2-byte transfer at 1 MHz (``SPI_SPEED``); the reset sequence
writes PWR_MGMT_1.DEVICE_RESET, then checks WHO_AM_I and PWR_MGMT_1 == 0x40, wakes the
chip (CLKSEL = 1) and resets the signal paths; configuration is PX4's set-and-clear
read-modify-write of seven registers, each checked afterwards. Sensor reads run at
5 MHz (PX4's ``SPI_SPEED_SENSOR``). PX4 reads samples through the FIFO; the emulated
chip has no FIFO, so :meth:`Mpu6000Driver.read_sample` burst-reads the 14 data
registers ACCEL_XOUT_H..GYRO_ZOUT_L in one transfer instead (what PX4's pre-FIFO driver
did). Values are returned in the chip's own axes; the rig applies board rotation.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from fpga_hdl.buses.transactions import BusError, SpiBus
from fpga_hdl.chips.mpu6000 import regs

SPI_SPEED_HZ = 1e6  # PX4 InvenSense_MPU6000::SPI_SPEED
SPI_SPEED_SENSOR_HZ = 5e6  # PX4 InvenSense_MPU6000::SPI_SPEED_SENSOR

#: PX4 MPU6000::_register_cfg: (register, set bits, clear bits).
PX4_REGISTER_CONFIG = (
    (regs.Reg.GYRO_CONFIG, 0x18, 0xE0),  # FS_SEL_2000_DPS; clear self-test bits
    (regs.Reg.ACCEL_CONFIG, 0x18, 0xE0),  # AFS_SEL_16G; clear self-test bits
    (regs.Reg.FIFO_EN, 0x78, 0x80),  # XG, YG, ZG, ACCEL into the FIFO; not TEMP
    (regs.Reg.INT_PIN_CFG, 0x80, 0x00),  # INT_LEVEL (active low)
    (regs.Reg.INT_ENABLE, 0x01, 0x00),  # DATA_RDY_INT_EN
    (regs.Reg.USER_CTRL, 0x50, 0x00),  # FIFO_EN | I2C_IF_DIS
    (regs.Reg.PWR_MGMT_1, 0x01, regs.PWR_MGMT_1_SLEEP),  # CLKSEL_0, awake
)


class Mpu6000Error(BusError):
    """The chip answered, but not as an MPU-6000 configured by this driver would."""


@dataclass(frozen=True)
class ImuReading:
    """One decoded burst, SI units, the chip's axes."""

    accel_mps2: tuple[float, float, float]
    gyro_rads: tuple[float, float, float]
    temperature_c: float


class Mpu6000Driver:
    """PX4's MPU-6000 transaction sequence over any :class:`SpiBus`."""

    def __init__(self, bus: SpiBus, device: str = "imu") -> None:
        self.bus = bus
        self.device = device
        self.gyro_config = 0
        self.accel_config = 0

    async def read_register(self, register: int) -> int:
        rx = await self.bus.transfer(
            self.device, bytes([register | regs.READ_FLAG, 0]), sclk_hz=SPI_SPEED_HZ
        )
        return rx[1]

    async def write_register(self, register: int, value: int) -> None:
        await self.bus.transfer(self.device, bytes([register, value]), sclk_hz=SPI_SPEED_HZ)

    async def set_and_clear(self, register: int, set_bits: int, clear_bits: int) -> None:
        original = await self.read_register(register)
        value = (original & ~clear_bits) | set_bits
        if value != original:
            await self.write_register(register, value)

    async def reset(self) -> None:
        """PX4 STATE::RESET and STATE::WAIT_FOR_RESET (the 100 ms waits are the rig's)."""
        await self.write_register(regs.Reg.PWR_MGMT_1, regs.PWR_MGMT_1_DEVICE_RESET)
        who_am_i = await self.read_register(regs.Reg.WHO_AM_I)
        power = await self.read_register(regs.Reg.PWR_MGMT_1)
        if who_am_i != regs.WHO_AM_I_VALUE or power != regs.PWR_MGMT_1_SLEEP:
            raise Mpu6000Error(
                f"MPU-6000 reset not complete: WHO_AM_I=0x{who_am_i:02X} (expected 0x68), "
                f"PWR_MGMT_1=0x{power:02X} (expected 0x40)"
            )
        await self.write_register(regs.Reg.PWR_MGMT_1, 0x01)  # CLKSEL_0, wake up
        await self.write_register(regs.Reg.SIGNAL_PATH_RESET, 0x07)
        await self.write_register(regs.Reg.USER_CTRL, 0x11)  # SIG_COND_RESET | I2C_IF_DIS

    async def configure(self) -> None:
        """PX4 Configure(): set and clear bits, then check every register."""
        for register, set_bits, clear_bits in PX4_REGISTER_CONFIG:
            await self.set_and_clear(register, set_bits, clear_bits)
        for register, set_bits, clear_bits in PX4_REGISTER_CONFIG:
            value = await self.read_register(register)
            if value & set_bits != set_bits or value & clear_bits:
                raise Mpu6000Error(
                    f"MPU-6000 register 0x{register:02X} reads 0x{value:02X}: "
                    f"bits 0x{set_bits:02X} not set or 0x{clear_bits:02X} not clear"
                )
        self.gyro_config = await self.read_register(regs.Reg.GYRO_CONFIG)
        self.accel_config = await self.read_register(regs.Reg.ACCEL_CONFIG)

    async def start(self) -> None:
        await self.reset()
        await self.configure()

    async def read_raw(self) -> bytes:
        """One 15-byte transfer: read command, then ACCEL_XOUT_H..GYRO_ZOUT_L."""
        tx = bytes([regs.Reg.ACCEL_XOUT_H | regs.READ_FLAG]) + bytes(14)
        rx = await self.bus.transfer(self.device, tx, sclk_hz=SPI_SPEED_SENSOR_HZ)
        return rx[1:]

    async def read_sample(self) -> ImuReading:
        return decode(await self.read_raw(), self.gyro_config, self.accel_config)


def decode(data: bytes, gyro_config: int, accel_config: int) -> ImuReading:
    """14 data-register bytes to SI with the full-scale ranges in force."""
    if len(data) != 14:
        raise ValueError(f"MPU-6000 data block is 14 bytes, not {len(data)}")
    ax, ay, az, temp, gx, gy, gz = _DATA_REGISTERS.unpack(data)
    accel_scale = regs.accel_mps2_per_lsb(accel_config)
    gyro_scale = regs.gyro_rads_per_lsb(gyro_config)
    return ImuReading(
        accel_mps2=(ax * accel_scale, ay * accel_scale, az * accel_scale),
        gyro_rads=(gx * gyro_scale, gy * gyro_scale, gz * gyro_scale),
        temperature_c=temp / regs.TEMP_LSB_PER_C + regs.TEMP_OFFSET_C,
    )


#: ACCEL_XOUT_H .. GYRO_ZOUT_L: seven big-endian int16 (plain ``struct``: a frame decodes
#: one block, where numpy's per-call overhead was most of the cost).
_DATA_REGISTERS = struct.Struct(">7h")
