"""Transaction-level model of the MPU-6000 core: the same registers, byte for byte.

It follows ``core.Mpu6000`` exactly, including what the RTL does at the edges of the
datasheet: the command byte answers 0x00, a muted chip leaves SDO to the pull-up
(0xFF), FS_SEL/AFS_SEL shift and saturate the loaded finest-resolution sample, a
sample loaded while asleep is dropped, DEVICE_RESET restores every reset value.

The 14 data bytes are computed once per loaded sample and configuration (a new sample or
any register write makes them stale), and a burst inside the data registers is one slice
of them: PX4's 15-byte burst every frame is then a few hundred nanoseconds, where
recomputing every byte per byte read cost half of a TLM frame.
"""

from __future__ import annotations

from fpga_hdl.chips.mpu6000 import regs

#: What a controller reads from an undriven SDO line: the pull-up.
IDLE_BYTE = 0xFF
_DATA_START = int(regs.Reg.ACCEL_XOUT_H)
_DATA_BYTES = 2 * len(regs.DATA_FIELDS)
_REGISTERS = {r.address: r for r in regs.CONFIG_REGISTERS}


class Mpu6000Model:
    """MPU-6000 registers behind an SPI transfer
    (a :class:`~fpga_hdl.buses.transactions.SpiDeviceModel`)."""

    def __init__(self) -> None:
        self._config = {r.address: r.reset_value for r in regs.CONFIG_REGISTERS}
        self._visible = regs.Mpu6000Sample(0, 0, 0, 0, 0, 0, 0)
        self._data: bytes | None = None  # ACCEL_XOUT_H..GYRO_ZOUT_L; None once stale
        self.fault_mute = False
        self.fault_flip = 0

    @property
    def sleeping(self) -> bool:
        return bool(self._config[regs.Reg.PWR_MGMT_1] & regs.PWR_MGMT_1_SLEEP)

    def load_sample(self, sample: regs.Mpu6000Sample) -> None:
        """Offer a sample; like the chip, one offered while asleep is not taken."""
        if not self.sleeping:
            self._visible = sample
            self._data = None

    def _data_bytes(self) -> bytes:
        if self._data is None:
            self._data = regs.data_register_bytes(
                self._visible, self._config[regs.Reg.GYRO_CONFIG],
                self._config[regs.Reg.ACCEL_CONFIG],
            )  # fmt: skip
        return self._data

    def read_register(self, address: int) -> int:
        if address in self._config:
            return self._config[address]
        if address == regs.Reg.WHO_AM_I:
            return regs.WHO_AM_I_VALUE
        offset = address - _DATA_START
        if 0 <= offset < _DATA_BYTES:
            return self._data_bytes()[offset]
        return 0x00

    def write_register(self, address: int, value: int) -> None:
        register = _REGISTERS.get(address)
        if register is None:
            return  # read-only or unimplemented: the chip ignores the write
        self._data = None  # a full-scale selector or a reset may have changed
        self._config[address] = value & ~register.self_clearing & 0xFF
        if address == regs.Reg.PWR_MGMT_1 and value & regs.PWR_MGMT_1_DEVICE_RESET:
            self._config = {r.address: r.reset_value for r in regs.CONFIG_REGISTERS}

    def transfer(self, tx: bytes) -> bytes:
        if not tx:
            return b""
        command, count = tx[0], len(tx) - 1
        address = command & 0x7F
        if command & regs.READ_FLAG:
            rx: bytes | bytearray = self._read_burst(address, count)
        else:  # each byte answers the register's value before the byte is written
            rx = bytearray()
            for byte in tx[1:]:
                rx.append(self.read_register(address))
                self.write_register(address, byte)
                address = (address + 1) & 0x7F
        if self.fault_mute:
            return bytes([IDLE_BYTE]) * len(tx)
        if self.fault_flip:
            rx = bytes(byte ^ self.fault_flip for byte in rx)
        return b"\x00" + rx

    def _read_burst(self, address: int, count: int) -> bytes:
        """``count`` registers from ``address`` on, auto-incrementing (wrapping after 0x7F)."""
        offset = address - _DATA_START
        if offset >= 0 and offset + count <= _DATA_BYTES:
            return self._data_bytes()[offset : offset + count]
        return bytes(self.read_register((address + i) & 0x7F) for i in range(count))
