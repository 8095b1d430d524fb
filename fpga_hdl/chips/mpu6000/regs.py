"""InvenSense MPU-6000 register map, sample layout, scale factors and SPI timing.

Sources: PS-MPU-6000A-00 rev 3.4 (product specification: §6.2 sensitivities, §6.4 SPI
operating frequencies, §6.8 SPI timing, §9.5 SPI interface) and RM-MPU-6000A-00 rev 4.2
(register map: addresses, reset values, FS_SEL/AFS_SEL, TEMP_OUT formula). PX4's driver
(src/drivers/imu/invensense/mpu6000/) uses the same addresses and bit names.

Defined once here and imported by the gateware (``core``), the transaction-level model
(``model``), the driver and the tests.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from amaranth.hdl import signed
from amaranth.lib import data

#: Standard gravity used by PX4 (CONSTANTS_ONE_G) to turn g into m/s².
STANDARD_GRAVITY_MPS2 = 9.80665
#: SPI read flag: bit 7 of the address byte (PS-MPU-6000A-00 §9.5).
READ_FLAG = 0x80
WHO_AM_I_VALUE = 0x68


class Reg(IntEnum):
    """Register addresses (RM-MPU-6000A-00 §3)."""

    SMPLRT_DIV = 0x19
    CONFIG = 0x1A
    GYRO_CONFIG = 0x1B
    ACCEL_CONFIG = 0x1C
    FIFO_EN = 0x23
    INT_PIN_CFG = 0x37
    INT_ENABLE = 0x38
    ACCEL_XOUT_H = 0x3B
    TEMP_OUT_H = 0x41
    GYRO_XOUT_H = 0x43
    GYRO_ZOUT_L = 0x48
    SIGNAL_PATH_RESET = 0x68
    USER_CTRL = 0x6A
    PWR_MGMT_1 = 0x6B
    PWR_MGMT_2 = 0x6C
    FIFO_COUNTH = 0x72
    FIFO_COUNTL = 0x73
    FIFO_R_W = 0x74
    WHO_AM_I = 0x75


#: PWR_MGMT_1 bits (RM-MPU-6000A-00 §4.28).
PWR_MGMT_1_DEVICE_RESET = 0x80
PWR_MGMT_1_SLEEP = 0x40


@dataclass(frozen=True)
class ConfigRegister:
    """A read/write configuration register as the chip stores it.

    ``self_clearing`` bits trigger an action when written as 1 and always read 0
    (PWR_MGMT_1.DEVICE_RESET, USER_CTRL's reset bits, SIGNAL_PATH_RESET).
    """

    address: int
    reset_value: int = 0x00
    self_clearing: int = 0x00


#: Every writable register; a write to any other address is ignored (read-only or absent).
CONFIG_REGISTERS = (
    ConfigRegister(Reg.SMPLRT_DIV),
    ConfigRegister(Reg.CONFIG),
    ConfigRegister(Reg.GYRO_CONFIG),
    ConfigRegister(Reg.ACCEL_CONFIG),
    ConfigRegister(Reg.FIFO_EN),
    ConfigRegister(Reg.INT_PIN_CFG),
    ConfigRegister(Reg.INT_ENABLE),
    ConfigRegister(Reg.SIGNAL_PATH_RESET, self_clearing=0x07),
    ConfigRegister(Reg.USER_CTRL, self_clearing=0x07),
    # Reset value 0x40 (SLEEP), RM-MPU-6000A-00 §3; PX4 waits for exactly this after reset.
    ConfigRegister(Reg.PWR_MGMT_1, reset_value=0x40, self_clearing=PWR_MGMT_1_DEVICE_RESET),
    ConfigRegister(Reg.PWR_MGMT_2),
)

#: FS_SEL / AFS_SEL occupy bits [4:3] of GYRO_CONFIG / ACCEL_CONFIG.
FULL_SCALE_SHIFT = 3
#: Sensitivity at FS_SEL = 0 (±250 °/s) and AFS_SEL = 0 (±2 g); each step up halves it
#: exactly (131, 65.5, 32.8, 16.4 LSB/(°/s); 16384 .. 2048 LSB/g), PS-MPU-6000A-00 §6.1-6.2.
GYRO_LSB_PER_DPS_FINEST = 131.0
ACCEL_LSB_PER_G_FINEST = 16384.0
#: TEMP_OUT: °C = raw / 340 + 36.53 (RM-MPU-6000A-00 §4.18).
TEMP_LSB_PER_C = 340.0
TEMP_OFFSET_C = 36.53

#: Data registers ACCEL_XOUT_H .. GYRO_ZOUT_L, in burst order.
DATA_FIELDS = ("accel_x", "accel_y", "accel_z", "temp", "gyro_x", "gyro_y", "gyro_z")
#: Raw width of one loaded accel/gyro sample. Loaded at the finest resolution (FS_SEL=0,
#: AFS_SEL=0) the widest range (±16 g, ±2000 °/s) needs 19 bits; 20 leave headroom so the
#: RTL saturates, as the chip does, instead of wrapping.
SAMPLE_BITS = 20
SAMPLE_LAYOUT = data.StructLayout(
    {name: signed(16 if name == "temp" else SAMPLE_BITS) for name in DATA_FIELDS}
)


@dataclass(frozen=True)
class SpiTiming:
    """SPI limits of PS-MPU-6000A-00 rev 3.4 §6.4 and §6.8 (times in seconds)."""

    sclk_max_all_registers_hz: float = 1e6  # §6.4: all registers, read/write
    sclk_max_sensor_registers_hz: float = 20e6  # §6.4: sensor and interrupt registers, read
    cs_setup_min_s: float = 8e-9  # t_SU.CS
    cs_hold_min_s: float = 500e-9  # t_HD.CS
    sdi_setup_min_s: float = 11e-9  # t_SU.SDI
    sdi_hold_min_s: float = 7e-9  # t_HD.SDI
    sdo_valid_max_s: float = 100e-9  # t_VD.SDO, from the falling SCLK edge
    sdo_hold_min_s: float = 4e-9  # t_HD.SDO


SPI_TIMING = SpiTiming()


def is_sensor_register(address: int) -> bool:
    """Registers the datasheet allows at 20 MHz: sensor data and interrupt status."""
    return Reg.ACCEL_XOUT_H - 1 <= address <= Reg.GYRO_ZOUT_L  # INT_STATUS 0x3A ..


@dataclass(frozen=True)
class Mpu6000Sample:
    """One loaded sample, raw at the finest resolution (the host port's words)."""

    accel_x: int
    accel_y: int
    accel_z: int
    temp: int
    gyro_x: int
    gyro_y: int
    gyro_z: int

    def __post_init__(self) -> None:
        for name in DATA_FIELDS:
            bits = 16 if name == "temp" else SAMPLE_BITS
            value = getattr(self, name)
            if not -(1 << (bits - 1)) <= value < 1 << (bits - 1):
                raise ValueError(f"MPU-6000 sample field {name}={value} does not fit {bits} bits")

    @classmethod
    def from_si(
        cls, accel_mps2: np.ndarray, gyro_rads: np.ndarray, temperature_c: float
    ) -> Mpu6000Sample:
        """Quantise SI values in the chip's axes, clamped to the loadable range.

        Scalar Python, not numpy: the rig converts one sample per frame, where numpy's
        per-call overhead cost ~30 µs (same IEEE operations, same round-half-even). The
        axes come out as Python floats by ``tolist``: ``float()`` of each numpy scalar took
        five times as long.
        """
        accel = tuple(np.asarray(accel_mps2, dtype=np.float64).ravel().tolist())
        gyro = tuple(np.asarray(gyro_rads, dtype=np.float64).ravel().tolist())
        if len(accel) != 3 or len(gyro) != 3:
            raise ValueError(f"accel and gyro must have 3 axes, not ({len(accel)},)/({len(gyro)},)")
        if not all(map(math.isfinite, accel + gyro)):
            raise ValueError(f"accel and gyro must be finite, not {accel}/{gyro}")
        ax, ay, az = _quantized([v / STANDARD_GRAVITY_MPS2 * ACCEL_LSB_PER_G_FINEST for v in accel])
        gx, gy, gz = _quantized([math.degrees(v) * GYRO_LSB_PER_DPS_FINEST for v in gyro])
        t = min(max(round((temperature_c - TEMP_OFFSET_C) * TEMP_LSB_PER_C), -32768), 32767)
        return cls(ax, ay, az, t, gx, gy, gz)

    def fields(self) -> dict[str, int]:
        return {name: getattr(self, name) for name in DATA_FIELDS}


_SAMPLE_MAX = (1 << (SAMPLE_BITS - 1)) - 1


def _quantized(lsbs: list[float]) -> list[int]:
    """Nearest loadable raw values (ties to even), saturated to the signed sample width."""
    low, high = -_SAMPLE_MAX - 1.0, float(_SAMPLE_MAX)
    return [round(min(max(lsb, low), high)) for lsb in lsbs]


def scaled_register_value(raw: int, full_scale_sel: int) -> int:
    """A 16-bit data register for a finest-resolution raw value: shift, then saturate.

    Each FS_SEL/AFS_SEL step halves the sensitivity, so the register is the raw value
    arithmetically shifted right by the selector, clamped to int16 like the chip's ADC.
    """
    return max(-32768, min(32767, raw >> full_scale_sel))


def data_register_bytes(sample: Mpu6000Sample, gyro_config: int, accel_config: int) -> bytes:
    """The 14 bytes ACCEL_XOUT_H .. GYRO_ZOUT_L for ``sample`` and the configuration."""
    afs = (accel_config >> FULL_SCALE_SHIFT) & 3
    fs = (gyro_config >> FULL_SCALE_SHIFT) & 3
    return _DATA_REGISTERS.pack(
        scaled_register_value(sample.accel_x, afs), scaled_register_value(sample.accel_y, afs),
        scaled_register_value(sample.accel_z, afs), sample.temp,
        scaled_register_value(sample.gyro_x, fs), scaled_register_value(sample.gyro_y, fs),
        scaled_register_value(sample.gyro_z, fs),
    )  # fmt: skip


#: The data registers as the chip lays them out: seven big-endian int16, in DATA_FIELDS order.
_DATA_REGISTERS = struct.Struct(">7h")


def accel_mps2_per_lsb(accel_config: int) -> float:
    afs = (accel_config >> FULL_SCALE_SHIFT) & 3
    return STANDARD_GRAVITY_MPS2 / (ACCEL_LSB_PER_G_FINEST / (1 << afs))


def gyro_rads_per_lsb(gyro_config: int) -> float:
    fs = (gyro_config >> FULL_SCALE_SHIFT) & 3
    return math.radians(1.0 / (GYRO_LSB_PER_DPS_FINEST / (1 << fs)))
