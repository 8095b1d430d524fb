"""Garmin LIDAR-Lite v3 register map and data format, defined once for the core, model,
driver and tests.

Sources: Garmin's "LIDAR-Lite v3 Operation Manual and Technical Specifications" (I2C
address 0x62, Fast-mode, the register table, STATUS bits, the 0x80 auto-increment bit of
the register pointer, distance in cm big-endian in FULL_DELAY_HIGH/LOW, range 40 m,
resolution 1 cm, ±2.5 cm accuracy above 1 m, about 270 Hz at the default acquisition
count), checked against PX4's ``src/drivers/distance_sensor/ll40ls/`` (LidarLiteI2C.h/.cpp:
the same address and registers, acquire command 0x04, the ``0x0F | 0x80`` distance read,
the high bit of the high byte as "invalid", the signal and peak strength registers and
their thresholds, SIG_COUNT_VAL set to 0xFF on reset, a measure/collect cycle of 50 ms).

Chosen here, because neither source fixes them:

- HW_VERSION (0x41) and SW_VERSION (0x4F) are not in the v3 manual; PX4 reads them to
  tell the versions apart and takes a part with HW_VERSION > 0 and UNIT_ID = 0 for "v1
  and v3" (25 m limit). The emulation answers 0x01 for both and 0 for UNIT_ID, so PX4
  classifies it as the v3 it is.
- Every register not listed reads 0x00 and ignores writes.
- No return: the v3 then reports 1 cm (a behaviour users of the part report; the manual
  is silent). PX4 marks that reading's quality 0 (below its 5 cm minimum).
"""

from dataclasses import dataclass
from enum import IntEnum

from amaranth.hdl import unsigned
from amaranth.lib import data

#: Factory 7-bit address (PX4 ``LL40LS_BASEADDR``).
DEFAULT_ADDRESS = 0x62

#: Register pointer byte: bits 6..0 are the register, bit 7 asks for auto-increment on
#: successive reads and writes (manual, "I2C Protocol Operation"; PX4 ``0x0F | 0x80``).
POINTER_REGISTER_MASK = 0x7F
POINTER_AUTO_INCREMENT = 0x80


class Register(IntEnum):
    """Register addresses (manual's control register list, PX4's ``LL40LS_*_REG``)."""

    ACQ_COMMAND = 0x00  # write: 0x00 reset, 0x03/0x04 take a distance measurement
    STATUS = 0x01  # busy, health, invalid signal
    SIG_COUNT_VAL = 0x02  # maximum acquisition count
    ACQ_CONFIG_REG = 0x04  # acquisition mode control
    PEAK_CORR = 0x0C  # peak value in the correlation record (PX4 "peak strength")
    SIGNAL_STRENGTH = 0x0E  # received signal strength
    FULL_DELAY_HIGH = 0x0F  # distance in cm, high byte
    FULL_DELAY_LOW = 0x10  # distance in cm, low byte
    REF_COUNT_VAL = 0x12  # reference acquisition count
    UNIT_ID_HIGH = 0x16
    UNIT_ID_LOW = 0x17
    THRESHOLD_BYPASS = 0x1C  # peak detection threshold bypass
    HW_VERSION = 0x41  # read by PX4's probe (see the module docstring)
    SW_VERSION = 0x4F


#: ACQ_COMMAND values.
ACQ_RESET = 0x00
ACQ_MEASURE_NO_BIAS = 0x03
ACQ_MEASURE = 0x04  # with receiver bias correction; PX4 ``LL40LS_MSRREG_ACQUIRE``
ACQ_MEASURE_COMMANDS = (ACQ_MEASURE_NO_BIAS, ACQ_MEASURE)

#: STATUS bits.
STATUS_BUSY = 0x01
STATUS_INVALID_SIGNAL = 0x08  # the last measurement found no return
STATUS_HEALTH = 0x20  # reference and receiver bias are operational

#: Read-write configuration registers and their reset values (manual); ACQ_COMMAND = 0x00
#: restores them.
STORED_REGISTERS: dict[Register, int] = {
    Register.SIG_COUNT_VAL: 0x80,
    Register.ACQ_CONFIG_REG: 0x08,
    Register.REF_COUNT_VAL: 0x05,
    Register.THRESHOLD_BYPASS: 0x00,
}

#: Read-only identification registers (module docstring).
ID_REGISTERS: dict[Register, int] = {
    Register.HW_VERSION: 0x01,
    Register.SW_VERSION: 0x01,
    Register.UNIT_ID_HIGH: 0x00,
    Register.UNIT_ID_LOW: 0x00,
}

#: One acquisition. The manual gives about 270 Hz (3.7 ms) at the default count 0x80;
#: the time grows with the count, and PX4 sets the maximum 0xFF, about twice as many
#: records, so 8 ms covers it. PX4 collects 50 ms after the command, well after.
ACQUISITION_TIME_US = 8000

#: Distance the v3 reports when nothing returns (module docstring).
NO_RETURN_CM = 1
#: Range limits (manual: 0-40 m at 70 % reflectivity; PX4's minimum 5 cm).
MAX_RANGE_M = 40.0
MIN_RANGE_M = 0.05
#: PX4's signal-quality thresholds (``LL40LS_SIGNAL_STRENGTH_LOW``, peak 135..234).
SIGNAL_STRENGTH_LOW = 24
PEAK_STRENGTH_LOW = 135
PEAK_STRENGTH_HIGH = 234

#: The raw measurement the host loads: distance in cm as the chip reports it, and the
#: two strengths PX4 turns into a signal quality.
SAMPLE_LAYOUT = data.StructLayout(
    {"distance_cm": unsigned(16), "signal_strength": unsigned(8), "peak_strength": unsigned(8)}
)


@dataclass(frozen=True)
class LidarLiteSample:
    """One measurement result as the chip's registers hold it."""

    distance_cm: int
    signal_strength: int
    peak_strength: int

    def __post_init__(self) -> None:
        for name, bits in (("distance_cm", 16), ("signal_strength", 8), ("peak_strength", 8)):
            value = getattr(self, name)
            if not 0 <= value < 1 << bits:
                raise ValueError(f"LIDAR-Lite sample {name} must fit {bits} bits, not {value}")

    @property
    def no_return(self) -> bool:
        """The acquisition found no return (signal strength 0)."""
        return self.signal_strength == 0

    def as_register_bits(self) -> int:
        """The sample packed as ``SAMPLE_LAYOUT`` bits (distance in the low 16 bits)."""
        return self.distance_cm | self.signal_strength << 16 | self.peak_strength << 24

    def fields(self) -> dict[str, int]:
        """The sample as host-port field values."""
        return {
            "distance_cm": self.distance_cm,
            "signal_strength": self.signal_strength,
            "peak_strength": self.peak_strength,
        }


def result_registers(sample: LidarLiteSample) -> dict[int, int]:
    """The registers one measurement result sets."""
    return {
        Register.PEAK_CORR: sample.peak_strength,
        Register.SIGNAL_STRENGTH: sample.signal_strength,
        Register.FULL_DELAY_HIGH: sample.distance_cm >> 8,
        Register.FULL_DELAY_LOW: sample.distance_cm & 0xFF,
    }


def next_pointer(pointer: int) -> int:
    """The pointer after one byte: +1 within the 7-bit register space when auto-increment
    is set, else unchanged."""
    if pointer & POINTER_AUTO_INCREMENT:
        return POINTER_AUTO_INCREMENT | (pointer + 1) & POINTER_REGISTER_MASK
    return pointer
