"""Transaction-level IST8310: the register behaviour of ``core.py`` in plain Python.

Used by :class:`fpga_hdl.buses.transactions.TlmI2cBus` for fast campaigns; the tests run the same
driver over this model and over the RTL and compare every byte. The six data bytes are
computed once per loaded sample and resolution, not once per byte read.
"""

from fpga_hdl.buses.transactions import I2cNack
from fpga_hdl.chips.ist8310 import regs
from fpga_hdl.chips.ist8310.regs import Ist8310Sample, Register

__all__ = ["Ist8310Model"]


class Ist8310Model:
    """One IST8310 at ``address``; ``now_us`` is simulated time, set by the rig.

    Each :meth:`write_read` is one whole transaction, so a sample loaded with
    :meth:`load_sample` is seen by the next transaction, as the RTL double buffer does.
    """

    def __init__(self, address: int = regs.DEFAULT_ADDRESS) -> None:
        regs.check_address(address)
        self.address = address
        self.now_us = 0
        #: Fault injection, as the core's ``fault_mute`` / ``fault_flip`` ports.
        self.fault_mute = False
        self.fault_flip = 0
        self._sample = Ist8310Sample(0, 0, 0)
        self._data: bytes | None = None  # DATAXL..DATAZH; None once sample or CNTL3 changed
        self.pointer = 0
        self._stored = dict.fromkeys(regs.STORED_REGISTERS, 0)
        self._measuring = False
        self._started_us = 0

    def load_sample(self, sample: Ist8310Sample) -> None:
        """Offer a new measurement result (the host port's ``sample_stb``)."""
        self._sample = sample
        self._data = None

    def write_read(self, write: bytes, read_len: int) -> bytes:
        """Write ``write`` (pointer, then registers), then read ``read_len`` bytes."""
        if self.fault_mute:
            raise I2cNack(self.address)
        if write:
            self.pointer = write[0]
            for byte in write[1:]:
                self._write_register(self.pointer, byte)
                self.pointer = (self.pointer + 1) & 0xFF
        out = bytearray()
        for _ in range(read_len):
            out.append(self._read_register(self.pointer) ^ self.fault_flip)
            self.pointer = (self.pointer + 1) & 0xFF
        return bytes(out)

    @property
    def _finished(self) -> bool:
        elapsed_us = (self.now_us - self._started_us) % 2**32
        return self._measuring and elapsed_us >= regs.MEASUREMENT_TIME_US

    def _read_register(self, address: int) -> int:
        finished = self._finished
        if address in regs.DATA_REGISTERS:
            if finished:
                self._measuring = False  # reading data clears DRDY
            if self._data is None:
                self._data = regs.data_bytes(self._sample, self._stored[Register.CNTL3])
            return self._data[address - Register.DATAXL]
        if address == Register.WAI:
            return regs.DEVICE_ID
        if address == Register.STAT1:
            return regs.STAT1_DRDY if finished else 0
        if address == Register.CNTL1:
            return regs.CNTL1_MODE_SINGLE if self._measuring and not finished else 0
        return self._stored[Register(address)] if address in self._stored else 0

    def _write_register(self, address: int, byte: int) -> None:
        self._data = None  # CNTL3 (resolution) or a soft reset may have changed
        if address == Register.CNTL1:
            self._measuring = byte & regs.CNTL1_MODE_MASK == regs.CNTL1_MODE_SINGLE
            self._started_us = self.now_us % 2**32
        elif address == Register.CNTL2 and byte & regs.CNTL2_SRST:
            self._measuring = False
            self._stored = dict.fromkeys(regs.STORED_REGISTERS, 0)
        elif address in regs.STORED_REGISTERS:
            register = Register(address)
            self._stored[register] = byte & regs.STORED_REGISTERS[register]
