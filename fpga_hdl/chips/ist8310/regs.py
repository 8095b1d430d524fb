"""IST8310 register map and data format, defined once for the core, model, driver and tests.

Sources: iSentek IST8310 datasheet (register table, 7-bit addresses 0x0C..0x0F selected by
the CAD pins, 0.3 µT/LSB in the default 14-bit output), checked against PX4's
``src/drivers/magnetometer/isentek/ist8310/iSentek_IST8310_registers.hpp`` (addresses,
STAT1.DRDY, CNTL1 single measurement, CNTL2.SRST, CNTL3 16-bit output at 1320 LSB/G,
AVGCNTL 16x averaging with ODRmax 166 Hz, PDCNTL normal pulse) and ``IST8310.cpp``.

Reset values of the control registers are not in the sources available to us; they
reset to 0x00 here. PX4 sets and checks every bit it relies on, so its behaviour does
not depend on them.
"""

from dataclasses import dataclass
from enum import IntEnum

from amaranth.hdl import signed
from amaranth.lib import data

#: 7-bit addresses the CAD1/CAD0 pins select; 0x0E is the default PX4 probes.
ADDRESSES = (0x0C, 0x0D, 0x0E, 0x0F)
DEFAULT_ADDRESS = 0x0E


def check_address(address: int) -> None:
    """Reject an address the chip's two address pins cannot select (core and model alike)."""
    if address not in ADDRESSES:
        choices = ", ".join(f"0x{a:02X}" for a in ADDRESSES)
        raise ValueError(f"IST8310 address must be one of {choices}, not {address!r}")


#: WAI (Who Am I) value.
DEVICE_ID = 0x10


class Register(IntEnum):
    """Register addresses (datasheet register table, PX4 ``Register``)."""

    WAI = 0x00  # device ID, read-only
    STAT1 = 0x02  # status 1: DRDY, DOR
    DATAXL = 0x03  # X output, little-endian int16
    DATAXH = 0x04
    DATAYL = 0x05
    DATAYH = 0x06
    DATAZL = 0x07
    DATAZH = 0x08
    STAT2 = 0x09  # status 2 (interrupt status; not emulated, reads 0)
    CNTL1 = 0x0A  # operating mode
    CNTL2 = 0x0B  # soft reset, DRDY pin control
    STR = 0x0C  # self-test
    CNTL3 = 0x0D  # output resolution per axis
    TEMPL = 0x1C  # temperature (not emulated, reads 0)
    TEMPH = 0x1D
    TCCNTL = 0x40  # temperature compensation control
    AVGCNTL = 0x41  # averaging
    PDCNTL = 0x42  # set/reset pulse duration


#: STAT1 bit 0: data ready. Set when a single measurement completes, cleared by reading
#: a data register (DATAXL..DATAZH).
STAT1_DRDY = 0x01
#: CNTL1 mode field value that starts one measurement; the chip then returns to standby.
CNTL1_MODE_SINGLE = 0x01
CNTL1_MODE_MASK = 0x0F
#: CNTL2 bit 0: soft reset, same as power-on reset; reads back 0 once done.
CNTL2_SRST = 0x01
#: CNTL3 bits 4..6: 16-bit output for X, Y, Z (1320 LSB/G instead of 330 LSB/G).
CNTL3_X_16BIT = 0x10
CNTL3_Y_16BIT = 0x20
CNTL3_Z_16BIT = 0x40
#: AVGCNTL: 16x averaging on Y (bits 5:3 = 0b100) and on X/Z (bits 2:0 = 0b100).
AVGCNTL_16X = 0x24
#: PDCNTL bits 7:6 = 0b11: normal pulse duration ("please use this setting").
PDCNTL_NORMAL = 0xC0

#: Registers that store what is written (masked) and read it back; the rest have
#: behaviour (WAI, STAT1, data, CNTL1) or are not emulated and read 0.
#: CNTL2.SRST is not stored: writing it resets the chip.
STORED_REGISTERS: dict[Register, int] = {
    Register.CNTL2: 0xFF & ~CNTL2_SRST,
    Register.STR: 0xFF,
    Register.CNTL3: 0xFF,
    Register.TCCNTL: 0xFF,
    Register.AVGCNTL: 0xFF,
    Register.PDCNTL: 0xFF,
}

#: Data registers in address order: (axis, high byte?).
DATA_REGISTERS = (
    Register.DATAXL,
    Register.DATAXH,
    Register.DATAYL,
    Register.DATAYH,
    Register.DATAZL,
    Register.DATAZH,
)

#: Single-measurement time. PX4 configures 16x averaging, whose maximum output rate is
#: 166 Hz (PX4 AVGCNTL comment: "wait at least 6 ms"). The emulation uses this, the
#: longest averaging setting, for every AVGCNTL value: a driver that waits long enough
#: for the chip's slowest setting is never told data is ready too early.
MEASUREMENT_TIME_US = 6000

#: Output sensitivity with CNTL3 16-bit output (PX4 ``set_scale(1.f / 1320.f)``).
LSB_PER_GAUSS_16BIT = 1320
#: Default 14-bit output: 0.3 µT/LSB in the datasheet, exactly a quarter of 16-bit mode.
LSB_PER_GAUSS_14BIT = 330
#: 16-bit counts to 14-bit counts: arithmetic shift right by this many bits.
SHIFT_14BIT = 2

#: The raw sample the host loads: the field as 16-bit-mode counts (1320 LSB/G) in the
#: chip's own axes (x forward, y right, z up on PX4's reference board).
SAMPLE_LAYOUT = data.StructLayout({"x": signed(16), "y": signed(16), "z": signed(16)})


@dataclass(frozen=True)
class Ist8310Sample:
    """One magnetometer sample in 16-bit-mode counts, chip axes."""

    x_counts: int
    y_counts: int
    z_counts: int

    def __post_init__(self) -> None:
        for name in ("x_counts", "y_counts", "z_counts"):
            value = getattr(self, name)
            if not -32768 <= value <= 32767:
                raise ValueError(f"IST8310 sample {name} must fit int16, not {value}")

    def as_register_bits(self) -> int:
        """The sample packed as ``SAMPLE_LAYOUT`` bits (x in the low 16 bits)."""
        mask = 0xFFFF
        return (self.x_counts & mask) | (self.y_counts & mask) << 16 | (self.z_counts & mask) << 32


def data_bytes(sample: Ist8310Sample, cntl3: int) -> bytes:
    """DATAXL..DATAZH for ``sample`` at the resolution CNTL3 selects (little-endian)."""
    out = bytearray()
    for counts, bit in (
        (sample.x_counts, CNTL3_X_16BIT),
        (sample.y_counts, CNTL3_Y_16BIT),
        (sample.z_counts, CNTL3_Z_16BIT),
    ):
        value = counts if cntl3 & bit else counts >> SHIFT_14BIT
        out += value.to_bytes(2, "little", signed=True)
    return bytes(out)
