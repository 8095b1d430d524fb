"""PixArt PMW3901MB optical-flow chip: register map, sample layout, SPI timing, optics and the
performance-optimisation sequence, defined once for the core, model, driver and tests.

Sources, and what each one confirms:

- PixArt's "PMW3901MB-TXQT Product Datasheet" v1.10 (20 June 2017): 4-wire SPI at 2 MHz,
  working range 80 mm to infinity, 16-bit motion registers, the power-up sequence (write
  0x5A to Power_Up_Reset, read Motion and the four Delta registers once, then the
  performance-optimisation registers in the datasheet's order).
- PX4's ``src/drivers/optical_flow/pmw3901/PMW3901.cpp`` (release 1.17): the register
  addresses it uses, Product_ID 0x49, the write bit 0x80, the 2 MHz bus, the whole
  optimisation sequence with its reads of bank 0x0E and their branches, t_SWW = 10.5 µs
  after each write, a 7.4 rad/s maximum rate and the 80 mm minimum ("Datasheet: ...").
- PX4's PixArt PAW3902 and PAA3905 register headers (the same family, Product_ID 0x49
  for the PAW3902): Motion bit 7 = MOT, the 12-byte Motion_Burst order, the 13-bit
  shutter, SPI mode 3, 126 frames per second, and the family's SPI gaps t_SWR = 6 µs,
  t_SRW = t_SRR = 1.5 µs, t_SRAD = 2 µs.
- LibDriver's PMW3901MB driver: Inverse_Product_ID 0xB6, Shutdown = write 0xB6 to 0x3B,
  the burst's byte order, Shutter_Upper bits 4..0, SQUAL × 4 = features.

Not confirmed by any source read here (the value used, and where it comes from):

- Revision_ID = 0x00: the value Pimoroni's PMW3901 driver checks (PX4 does not read it).
- t_BEXIT = 500 ns, t_NCS-SCLK = 120 ns, t_SCLK-NCS = 120 ns after a read and 20 µs
  after a write, SDO valid 120 ns after the falling SCLK edge: PixArt's other SPI
  sensors (ADNS-5020, PAW3395); the PMW3901MB table was not found.
- Observation reads 0x3F while the chip tracks: the PAA3905's "working correctly" value.
- 42° field of view and 35 × 35 pixels: the figures commonly quoted for the part, not in
  the datasheet pages read.
- The registers of bank 0x0E PX4 reads during its sequence (0x67, 0x73, 0x70, 0x71) hold
  factory trim the datasheet does not document: chosen so that PX4 takes its longer
  branch (bit 7 of 0x67 set, 0x73 = 0, then it rewrites 0x70/0x71 from them).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from amaranth.hdl import signed, unsigned
from amaranth.lib import data

#: Bit 7 of the address byte: set for a write, clear for a read (PX4 ``DIR_WRITE``).
WRITE_FLAG = 0x80
PRODUCT_ID_VALUE = 0x49
REVISION_ID_VALUE = 0x00
INVERSE_PRODUCT_ID_VALUE = 0xB6
#: Power_Up_Reset takes this value (any other is ignored).
POWER_UP_RESET_VALUE = 0x5A
#: Shutdown takes this value: the chip stops until the next power-up reset.
SHUTDOWN_VALUE = 0xB6
#: Motion bit 7: motion since the last report.
MOTION_MOT = 0x80
#: Observation while the chip tracks (module docstring).
OBSERVATION_TRACKING = 0x3F


class Reg(IntEnum):
    """Register addresses of bank 0 (the datasheet's map); BANK_SELECT works in every bank."""

    PRODUCT_ID = 0x00
    REVISION_ID = 0x01
    MOTION = 0x02
    DELTA_X_L = 0x03
    DELTA_X_H = 0x04
    DELTA_Y_L = 0x05
    DELTA_Y_H = 0x06
    SQUAL = 0x07
    RAW_DATA_SUM = 0x08
    MAXIMUM_RAW_DATA = 0x09
    MINIMUM_RAW_DATA = 0x0A
    SHUTTER_LOWER = 0x0B
    SHUTTER_UPPER = 0x0C
    OBSERVATION = 0x15
    MOTION_BURST = 0x16
    POWER_UP_RESET = 0x3A
    SHUTDOWN = 0x3B
    INVERSE_PRODUCT_ID = 0x5F
    BANK_SELECT = 0x7F


#: The Delta registers in address order, which a read clears (see ``core``).
DELTA_REGISTERS = (Reg.DELTA_X_L, Reg.DELTA_X_H, Reg.DELTA_Y_L, Reg.DELTA_Y_H)
#: What Motion_Burst sends after its address, in order (the burst's index of each).
BURST_ORDER = (
    Reg.MOTION, Reg.OBSERVATION, *DELTA_REGISTERS, Reg.SQUAL, Reg.RAW_DATA_SUM,
    Reg.MAXIMUM_RAW_DATA, Reg.MINIMUM_RAW_DATA, Reg.SHUTTER_UPPER, Reg.SHUTTER_LOWER,
)  # fmt: skip
BURST_LENGTH = len(BURST_ORDER)

#: The chip's own faults, bits 0.. of its fault word's own part (``host_port.fault_word``);
#: ``core.Pmw3901`` defines each.
OWN_FAULTS = ("stuck", "zero_quality", "drop_frames")
FAULT_STUCK, FAULT_ZERO_QUALITY, FAULT_DROP_FRAMES = (1 << i for i in range(len(OWN_FAULTS)))
#: Each own fault's bit, by name.
FAULT_BITS = {name: 1 << i for i, name in enumerate(OWN_FAULTS)}

SHUTTER_BITS = 13
#: One camera frame as the host loads it (the host port's ``flow`` channel).
SAMPLE_LAYOUT = data.StructLayout(
    {
        "delta_x": signed(16),
        "delta_y": signed(16),
        "squal": unsigned(8),
        "shutter": unsigned(SHUTTER_BITS),
        "raw_sum": unsigned(8),
        "raw_max": unsigned(8),
        "raw_min": unsigned(8),
    }
)


@dataclass(frozen=True)
class Pmw3901Sample:
    """One camera frame as the host loads it."""

    delta_x: int  # counts this frame, signed (the chip accumulates)
    delta_y: int
    squal: int  # 0..255 surface quality of this frame (features / 4)
    shutter: int  # exposure, 13 bits (Shutter_Upper[4:0], Shutter_Lower)
    raw_sum: int = 0  # RawData_Sum, Maximum_RawData, Minimum_RawData: image statistics
    raw_max: int = 0  # PX4 does not read them; 0 unless a test sets them
    raw_min: int = 0

    def __post_init__(self) -> None:
        for name, field in SAMPLE_LAYOUT:
            shape = field.shape
            low = -(1 << (shape.width - 1)) if shape.signed else 0
            high = (1 << (shape.width - 1 if shape.signed else shape.width)) - 1
            value = getattr(self, name)
            if not low <= value <= high:
                raise ValueError(f"PMW3901 sample {name}={value} outside {low}..{high}")

    def fields(self) -> dict[str, int]:
        """The sample as host-port field values."""
        return {name: getattr(self, name) for name, _ in SAMPLE_LAYOUT}

    def as_register_bits(self) -> int:
        """The sample packed as ``SAMPLE_LAYOUT`` bits (a testbench drives them at once)."""
        bits = 0
        for name, field in SAMPLE_LAYOUT:
            width = field.shape.width
            bits |= (getattr(self, name) & ((1 << width) - 1)) << field.offset
        return bits


def saturated_int16(value: int) -> int:
    """The accumulators' arithmetic: clamp to a signed 16-bit register."""
    return max(-32768, min(32767, value))


@dataclass(frozen=True)
class SpiTiming:
    """SPI limits (seconds, hertz); the module docstring names each value's source."""

    sclk_max_hz: float = 2e6  # datasheet: 4-wire SPI at 2 MHz
    mode: int = 3  # SCLK idles high, SDO changes on the falling edge
    ncs_sclk_min_s: float = 120e-9  # t_NCS-SCLK: NCS low to the first SCLK edge
    sclk_ncs_read_min_s: float = 120e-9  # t_SCLK-NCS after a read's last data bit
    sclk_ncs_write_min_s: float = 20e-6  # t_SCLK-NCS after a write's last data bit
    sdo_valid_max_s: float = 120e-9  # SDO valid after the falling SCLK edge
    srad_min_s: float = 2e-6  # t_SRAD: a read's address to its first data bit
    sww_min_s: float = 10.5e-6  # t_SWW: one write's last data bit to the next's
    swr_min_s: float = 6e-6  # t_SWR: a write's last data bit to a read's address
    srw_srr_min_s: float = 1.5e-6  # t_SRW, t_SRR: a read's last bit to the next command
    bexit_min_s: float = 500e-9  # t_BEXIT: NCS high after a motion burst


SPI_TIMING = SpiTiming()


# The datasheet's performance-optimisation sequence, as PX4's ``sensorInit`` writes it:
# (register, value) writes, with bank select (0x7F) among them. The reads that decide
# PX4's two branches sit between the parts; ``driver.Pmw3901Driver.init`` runs them.
BANK = int(Reg.BANK_SELECT)
OPTIMISATION_START = ((BANK, 0x00), (0x55, 0x01), (0x50, 0x07), (BANK, 0x0E), (0x43, 0x10))
#: Bank 0x0E register 0x48 after reading 0x67: bit 7 set → 0x04, else 0x02.
TRIM_BRANCH_REGISTER = 0x48
TRIM_BRANCH_VALUES = (0x02, 0x04)
OPTIMISATION_MIDDLE = ((BANK, 0x00), (0x51, 0x7B), (0x50, 0x00), (0x55, 0x00), (BANK, 0x0E))
#: Written when bank 0x0E register 0x73 reads 0, then 0x70 and 0x71 from their reads.
OPTIMISATION_TRIM = ((BANK, 0x00), (0x61, 0xAD), (0x51, 0x70), (BANK, 0x0E))
TRIM_REGISTERS = (0x70, 0x71)
OPTIMISATION_MAIN = (
    (BANK, 0x00), (0x61, 0xAD), (BANK, 0x03), (0x40, 0x00), (BANK, 0x05), (0x41, 0xB3),
    (0x43, 0xF1), (0x45, 0x14), (0x5B, 0x32), (0x5F, 0x34), (0x7B, 0x08), (BANK, 0x06),
    (0x44, 0x1B), (0x40, 0xBF), (0x4E, 0x3F), (BANK, 0x08), (0x65, 0x20), (0x6A, 0x18),
    (BANK, 0x09), (0x4F, 0xAF), (0x5F, 0x40), (0x48, 0x80), (0x49, 0x80), (0x57, 0x77),
    (0x60, 0x78), (0x61, 0x78), (0x62, 0x08), (0x63, 0x50), (BANK, 0x0A), (0x45, 0x60),
    (BANK, 0x00), (0x4D, 0x11), (0x55, 0x80), (0x74, 0x21), (0x75, 0x1F), (0x4A, 0x78),
    (0x4B, 0x78), (0x44, 0x08), (0x45, 0x50), (0x64, 0xFF), (0x65, 0x1F), (BANK, 0x14),
    (0x65, 0x67), (0x66, 0x08), (0x63, 0x70), (BANK, 0x15), (0x48, 0x48), (BANK, 0x07),
    (0x41, 0x0D), (0x43, 0x14), (0x4B, 0x0E), (0x45, 0x0F), (0x44, 0x42), (0x4C, 0x80),
    (BANK, 0x10), (0x5B, 0x02), (BANK, 0x07), (0x40, 0x41), (0x70, 0x00),
)  # fmt: skip
#: After a 10 ms wait; the last write (bank 0, 0x40 = 0x80) lets the chip track.
OPTIMISATION_FINAL = (
    (0x32, 0x44), (BANK, 0x07), (0x40, 0x40), (BANK, 0x06), (0x62, 0xF0), (0x63, 0x00),
    (BANK, 0x0D), (0x48, 0xC0), (0x6F, 0xD5), (BANK, 0x00), (0x5B, 0xA0), (0x4E, 0xA8),
    (0x5A, 0x50), (0x40, 0x80),
)  # fmt: skip
#: The write that completes the sequence: (bank, register, value).
TRACKING_WRITE = (0x00, *OPTIMISATION_FINAL[-1])
#: Bank 0x0E registers PX4 reads to choose its branches: their values (module docstring).
TRIM_BANK = 0x0E
TRIM_READ_REGISTER, TRIM_SKIP_REGISTER = 0x67, 0x73
TRIM_READ_ONLY = {TRIM_READ_REGISTER: 0x80, TRIM_SKIP_REGISTER: 0x00}
TRIM_INITIAL = {0x70: 0x1A, 0x71: 0x40}


def _written_registers() -> tuple[tuple[int, int], ...]:
    """Every (bank, register) the sequence writes, in first-write order."""
    parts = (OPTIMISATION_START, OPTIMISATION_MIDDLE, OPTIMISATION_TRIM, OPTIMISATION_MAIN,
             OPTIMISATION_FINAL)  # fmt: skip
    bank, seen = 0, dict[tuple[int, int], None]()
    for register, value in (write for part in parts for write in part):
        if register == BANK:
            bank = value
        else:
            seen.setdefault((bank, register), None)
    seen.setdefault((TRIM_BANK, TRIM_BRANCH_REGISTER), None)
    for register in TRIM_REGISTERS:
        seen.setdefault((TRIM_BANK, register), None)
    return tuple(seen)


#: The banked registers the chip stores (the ones the sequence writes; every other
#: banked register reads 0 and ignores writes), with their power-up values.
STORED_REGISTERS: dict[tuple[int, int], int] = {
    key: TRIM_INITIAL.get(key[1], 0) if key[0] == TRIM_BANK else 0 for key in _written_registers()
}
