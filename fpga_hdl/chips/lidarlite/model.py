"""Transaction-level LIDAR-Lite v3: the register behaviour of ``core.py`` in plain Python.

Used by :class:`fpga_hdl.buses.transactions.TlmI2cBus`; the tests run the same driver
over this model and over the RTL and compare every byte.
"""

from fpga_hdl.buses.transactions import I2cNack
from fpga_hdl.chips.lidarlite import regs
from fpga_hdl.chips.lidarlite.regs import LidarLiteSample, Register

__all__ = ["LidarLiteModel"]

_NOTHING_MEASURED = LidarLiteSample(0, 0, 0)


class LidarLiteModel:
    """One LIDAR-Lite v3 at ``address``; ``now_us`` is simulated time, set by the rig.

    An acquire command measures the sample loaded at that moment; its result becomes
    readable ``regs.ACQUISITION_TIME_US`` later, until then the previous result reads
    and STATUS says busy. Each :meth:`write_read` is one whole transaction, so a sample
    loaded with :meth:`load_sample` is seen by the next transaction, as the RTL double
    buffer does.
    """

    def __init__(self, address: int = regs.DEFAULT_ADDRESS) -> None:
        self.address = address
        self.now_us = 0
        #: Fault injection, as the core's ``fault_mute`` / ``fault_flip`` ports.
        self.fault_mute = False
        self.fault_flip = 0
        self.pointer = 0
        self._sample = _NOTHING_MEASURED  # the scene the next acquisition measures
        self._measured = _NOTHING_MEASURED  # the running (or finished) acquisition's result
        self._previous = _NOTHING_MEASURED  # what reads while an acquisition runs
        self._stored = dict(regs.STORED_REGISTERS)
        self._measuring = False
        self._started_us = 0

    def load_sample(self, sample: LidarLiteSample) -> None:
        """Offer the distance the next acquisition measures (the host port's ``sample_stb``)."""
        self._sample = sample

    def write_read(self, write: bytes, read_len: int) -> bytes:
        """Write ``write`` (pointer, then registers), then read ``read_len`` bytes."""
        if self.fault_mute:
            raise I2cNack(self.address)
        if write:
            self._settle()
            self.pointer = write[0]
            for byte in write[1:]:
                self._settle()
                self._write_register(self.pointer & regs.POINTER_REGISTER_MASK, byte)
                self.pointer = regs.next_pointer(self.pointer)
        out = bytearray()
        for _ in range(read_len):
            self._settle()
            out.append(self._read_register(self.pointer & regs.POINTER_REGISTER_MASK))
            self.pointer = regs.next_pointer(self.pointer)
        return bytes(b ^ self.fault_flip for b in out)

    @property
    def _finished(self) -> bool:
        elapsed_us = (self.now_us - self._started_us) % 2**32
        return self._measuring and elapsed_us >= regs.ACQUISITION_TIME_US

    @property
    def _shown(self) -> LidarLiteSample:
        return self._measured if self._finished else self._previous

    def _settle(self) -> None:
        """Every byte: a finished acquisition's result becomes the standing one, as the
        core does on each byte strobe (so ``now_us`` wrapping later cannot hide it)."""
        if self._finished:
            self._previous = self._measured
            self._measuring = False

    def _read_register(self, register: int) -> int:
        if register == Register.STATUS:
            busy = regs.STATUS_BUSY if self._measuring else 0
            invalid = regs.STATUS_INVALID_SIGNAL if self._shown.no_return else 0
            return regs.STATUS_HEALTH | busy | invalid
        result = regs.result_registers(self._shown).get(register)
        if result is not None:
            return result
        if register in self._stored:
            return self._stored[Register(register)]
        if register in regs.ID_REGISTERS:
            return regs.ID_REGISTERS[Register(register)]
        return 0

    def _write_register(self, register: int, byte: int) -> None:
        if register == Register.ACQ_COMMAND:
            if byte in regs.ACQ_MEASURE_COMMANDS:
                self._previous = self._shown
                self._measured = self._sample
                self._measuring = True
                self._started_us = self.now_us % 2**32
            elif byte == regs.ACQ_RESET:
                self._measuring = False
                self._stored = dict(regs.STORED_REGISTERS)
        elif register in self._stored:
            self._stored[Register(register)] = byte
