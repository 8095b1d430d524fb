"""Transaction-level PMW3901: the register behaviour of ``core.Pmw3901`` in plain Python.

A :class:`~fpga_hdl.buses.transactions.SpiDeviceModel`: one :meth:`Pmw3901Model.transfer`
per chip select, answering byte for byte what the core's SDO sends (0x00 during address
bytes and a write's data byte, the pull-up's 0xFF from a muted chip, ``fault_flip`` on
every byte read). The rules, the core's docstring states them.
"""

from __future__ import annotations

from fpga_hdl.chips.pmw3901 import regs
from fpga_hdl.chips.pmw3901.regs import Pmw3901Sample, Reg

__all__ = ["Pmw3901Model"]

#: What a controller reads from an undriven SDO line: the pull-up.
IDLE_BYTE = 0xFF
_NO_IMAGE = Pmw3901Sample(0, 0, 0, 0)
_CONSTANTS = {
    Reg.PRODUCT_ID: regs.PRODUCT_ID_VALUE,
    Reg.REVISION_ID: regs.REVISION_ID_VALUE,
    Reg.INVERSE_PRODUCT_ID: regs.INVERSE_PRODUCT_ID_VALUE,
}


class Pmw3901Model:
    """One PMW3901; :meth:`load_sample` is the host port's ``flow`` channel."""

    def __init__(self) -> None:
        #: Fault injection, as the core's fault inputs (``fault_own``: ``regs.FAULT_*``).
        self.fault_mute = False
        self.fault_flip = 0
        self._fault_own = 0
        self._image = _NO_IMAGE  # the last frame taken: SQUAL, shutter, raw data
        self._acc_x = self._acc_y = 0
        self._moved = False
        self._frozen = [0, 0, 0, 0]  # Delta_X_L, Delta_X_H, Delta_Y_L, Delta_Y_H
        self._frozen_mot = False
        self._bank = 0
        self._stored = dict(regs.STORED_REGISTERS)
        self._reset_seen = False
        self.tracking = False

    @property
    def fault_own(self) -> int:
        return self._fault_own

    @fault_own.setter
    def fault_own(self, mask: int) -> None:
        self._fault_own = mask
        if mask & regs.FAULT_DROP_FRAMES:
            self._clear_motion()

    def _clear_motion(self) -> None:
        self._acc_x = self._acc_y = 0
        self._moved = False

    def load_sample(self, sample: Pmw3901Sample) -> None:
        """One camera frame: taken only while the chip tracks and no fault stops it."""
        if not self.tracking or self._fault_own & (regs.FAULT_STUCK | regs.FAULT_DROP_FRAMES):
            return
        self._image = sample
        self._acc_x = regs.saturated_int16(self._acc_x + sample.delta_x)
        self._acc_y = regs.saturated_int16(self._acc_y + sample.delta_y)
        self._moved |= bool(sample.delta_x or sample.delta_y)

    @property
    def stored(self) -> dict[tuple[int, int], int]:
        """The banked registers as the optimisation sequence left them."""
        return dict(self._stored)

    def _freeze(self) -> None:
        """Motion read or burst: the accumulated motion moves to the Delta registers."""
        self._frozen = [*(self._acc_x & 0xFFFF).to_bytes(2, "little"),
                        *(self._acc_y & 0xFFFF).to_bytes(2, "little")]  # fmt: skip
        self._frozen_mot = self._moved
        self._clear_motion()

    def _image_byte(self, register: int) -> int:
        image = self._image
        if not self.tracking:
            return 0
        if register == Reg.SQUAL:
            return 0 if self._fault_own & regs.FAULT_ZERO_QUALITY else image.squal
        values = {
            Reg.RAW_DATA_SUM: image.raw_sum,
            Reg.MAXIMUM_RAW_DATA: image.raw_max,
            Reg.MINIMUM_RAW_DATA: image.raw_min,
            Reg.SHUTTER_LOWER: image.shutter & 0xFF,
            Reg.SHUTTER_UPPER: image.shutter >> 8,
            Reg.OBSERVATION: regs.OBSERVATION_TRACKING,
        }
        return values[Reg(register)]

    def _read(self, register: int) -> int:
        """A register's value; a Delta register reads 0 after it has been read."""
        if register == Reg.BANK_SELECT:
            return self._bank
        if self._bank != 0:
            if self._bank == regs.TRIM_BANK and register in regs.TRIM_READ_ONLY:
                return regs.TRIM_READ_ONLY[register]
            return self._stored.get((self._bank, register), 0)
        if register in _CONSTANTS:
            return _CONSTANTS[Reg(register)]
        if register == Reg.MOTION:
            return regs.MOTION_MOT if self._frozen_mot else 0
        if register in regs.DELTA_REGISTERS:
            index = register - Reg.DELTA_X_L
            value, self._frozen[index] = self._frozen[index], 0
            return value
        if Reg.SQUAL <= register <= Reg.SHUTTER_UPPER or register == Reg.OBSERVATION:
            return self._image_byte(register)
        return self._stored.get((0, register), 0)

    def _write(self, register: int, value: int) -> None:
        if register == Reg.BANK_SELECT:
            self._bank = value
        elif self._bank == 0 and register == Reg.POWER_UP_RESET:
            if value == regs.POWER_UP_RESET_VALUE:
                self._power_up_reset()
        elif self._bank == 0 and register == Reg.SHUTDOWN:
            if value == regs.SHUTDOWN_VALUE:
                self.tracking = self._reset_seen = False
        elif (self._bank, register) in self._stored:
            self._stored[(self._bank, register)] = value
            if (self._bank, register, value) == regs.TRACKING_WRITE and self._reset_seen:
                self.tracking = True

    def _power_up_reset(self) -> None:
        self._clear_motion()
        self._frozen = [0, 0, 0, 0]
        self._frozen_mot = False
        self._bank = 0
        self._stored = dict(regs.STORED_REGISTERS)
        self._reset_seen, self.tracking = True, False

    def transfer(self, tx: bytes) -> bytes:
        """One chip select: address/data pairs, or a motion burst after its address."""
        rx = bytearray()
        index = 0
        while index < len(tx):
            command, index = tx[index], index + 1
            rx.append(0)  # an address byte: SDO sends nothing
            address, reading = command & 0x7F, not command & regs.WRITE_FLAG
            if reading and self._bank == 0 and address in (Reg.MOTION, Reg.MOTION_BURST):
                self._freeze()  # at the address byte, whatever follows
            if reading and self._bank == 0 and address == Reg.MOTION_BURST:
                for position in range(len(tx) - index):
                    value = 0
                    if position < regs.BURST_LENGTH:
                        value = self._read(regs.BURST_ORDER[position])
                    rx.append(value ^ self.fault_flip)
                break
            if index == len(tx):
                break
            if reading:
                rx.append(self._read(address) ^ self.fault_flip)
            else:
                rx.append(0)
                self._write(address, tx[index])
            index += 1
        if self.fault_mute:
            return bytes([IDLE_BYTE]) * len(tx)
        return bytes(rx)
