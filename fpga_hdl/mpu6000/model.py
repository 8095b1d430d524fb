"""Transaction-level model of the MPU-6000 core: the same registers, byte for byte.

It follows ``core.Mpu6000`` exactly, including what the RTL does at the edges of the
datasheet: the command byte answers 0x00, a muted chip leaves SDO to the pull-up
(0xFF), FS_SEL/AFS_SEL shift and saturate the loaded finest-resolution sample, a
sample loaded while asleep is dropped, DEVICE_RESET restores every reset value.
"""

from __future__ import annotations

from fpga_hdl.mpu6000 import regs

#: What a controller reads from an undriven SDO line: the pull-up.
IDLE_BYTE = 0xFF


class Mpu6000Model:
    """MPU-6000 registers behind an SPI transfer (:class:`fpga_hdl.buses.SpiDeviceModel`)."""

    def __init__(self) -> None:
        self.config = {r.address: r.reset_value for r in regs.CONFIG_REGISTERS}
        self.visible = regs.Mpu6000Sample(0, 0, 0, 0, 0, 0, 0)
        self.fault_mute = False
        self.fault_flip = 0

    @property
    def sleeping(self) -> bool:
        return bool(self.config[regs.Reg.PWR_MGMT_1] & regs.PWR_MGMT_1_SLEEP)

    def load_sample(self, sample: regs.Mpu6000Sample) -> None:
        """Offer a sample; like the chip, one offered while asleep is not taken."""
        if not self.sleeping:
            self.visible = sample

    def read_register(self, address: int) -> int:
        if address in self.config:
            return self.config[address]
        if address == regs.Reg.WHO_AM_I:
            return regs.WHO_AM_I_VALUE
        offset = address - regs.Reg.ACCEL_XOUT_H
        if 0 <= offset < 2 * len(regs.DATA_FIELDS):
            data = regs.data_register_bytes(
                self.visible, self.config[regs.Reg.GYRO_CONFIG], self.config[regs.Reg.ACCEL_CONFIG]
            )
            return data[offset]
        return 0x00

    def write_register(self, address: int, value: int) -> None:
        by_address = {r.address: r for r in regs.CONFIG_REGISTERS}
        register = by_address.get(address)
        if register is None:
            return  # read-only or unimplemented: the chip ignores the write
        self.config[address] = value & ~register.self_clearing & 0xFF
        if address == regs.Reg.PWR_MGMT_1 and value & regs.PWR_MGMT_1_DEVICE_RESET:
            self.config = {r.address: r.reset_value for r in regs.CONFIG_REGISTERS}

    def transfer(self, tx: bytes) -> bytes:
        if not tx:
            return b""
        command, rx = tx[0], bytearray([0x00])
        address, writing = command & 0x7F, not command & regs.READ_FLAG
        for byte in tx[1:]:
            rx.append(self.read_register(address) ^ self.fault_flip)
            if writing:
                self.write_register(address, byte)
            address = (address + 1) & 0x7F
        if self.fault_mute:
            return bytes([IDLE_BYTE]) * len(tx)
        return bytes(rx)
