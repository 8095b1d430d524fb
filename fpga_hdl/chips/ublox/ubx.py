"""UBX protocol facts, defined once for the core, the TLM twin, the decoder and the tests.

Sources: u-blox M8 receiver description (UBX framing, NAV-PVT, ACK, CFG-PRT, CFG-MSG,
MON-VER) checked against PX4's ``PX4-GPSDrivers`` ``src/ubx.h`` (message IDs, payload
structs) and ``src/ubx.cpp`` (what its driver sends and reads).

A frame is ``0xB5 0x62, class, id, length (u16 little-endian), payload, CK_A, CK_B``. The
checksum is the 8-bit Fletcher sum over class..payload. Every frame the receiver sends is
described here as a tuple of byte *sources*: a constant, a byte of a named value, or one of
the two checksum bytes. :func:`render` turns sources into bytes (the TLM twin), and the core
builds its byte multiplexer from the very same tuples, so the two cannot disagree on a
layout.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Final, Literal

from amaranth.hdl import Shape, signed, unsigned
from amaranth.lib import data

SYNC1 = 0xB5
SYNC2 = 0x62
#: Bytes of a frame around its payload: sync (2), class, id, length (2), checksum (2).
FRAME_OVERHEAD = 8
#: Bytes before the payload: sync (2), class, id, length (2).
HEADER_LEN = 6

CLASS_NAV = 0x01
CLASS_ACK = 0x05
CLASS_CFG = 0x06
CLASS_MON = 0x0A

ID_NAV_PVT = 0x07
ID_NAV_STATUS = 0x03
ID_NAV_DOP = 0x04
ID_NAV_SVINFO = 0x30
ID_ACK_NAK = 0x00
ID_ACK_ACK = 0x01
ID_CFG_PRT = 0x00
ID_CFG_MSG = 0x01
ID_CFG_RATE = 0x08
ID_CFG_NAV5 = 0x24
ID_CFG_VALSET = 0x8A
ID_MON_VER = 0x04
ID_MON_HW = 0x09

#: CFG-PRT portID of UART1, the port the receiver is wired to.
PORT_UART1 = 0x01
#: CFG-PRT payload bytes per port block; baudRate is the u32 at offset 8.
CFG_PRT_BLOCK_LEN = 20
CFG_PRT_BAUD_OFFSET = 8
#: CFG-RATE's payload: measRate, navRate, timeRef (U2 each).
CFG_RATE_LEN = 6

#: Source of one frame byte: a constant, (value name, byte index little-endian), or a
#: checksum byte.
CK_A: Final = "ck_a"
CK_B: Final = "ck_b"
Source = int | tuple[str, int] | Literal["ck_a", "ck_b"]


def checksum(body: bytes | bytearray) -> tuple[int, int]:
    """UBX 8-bit Fletcher checksum (CK_A, CK_B) over class, id, length and payload."""
    ck_a = ck_b = 0
    for byte in body:
        ck_a = (ck_a + byte) & 0xFF
        ck_b = (ck_b + ck_a) & 0xFF
    return ck_a, ck_b


def frame(cls: int, msg_id: int, payload: bytes = b"") -> bytes:
    """One complete UBX frame with its checksum."""
    body = bytes([cls, msg_id]) + len(payload).to_bytes(2, "little") + payload
    return bytes([SYNC1, SYNC2]) + body + bytes(checksum(body))


def frame_sources(cls: int, msg_id: int, payload: Sequence[Source]) -> tuple[Source, ...]:
    """The byte sources of a frame whose payload bytes come from ``payload``."""
    length = len(payload)
    return (SYNC1, SYNC2, cls, msg_id, length & 0xFF, length >> 8, *payload, CK_A, CK_B)


def render(sources: Sequence[Source], values: Mapping[str, int]) -> bytes:
    """Bytes of a frame described by ``sources``, named bytes taken from ``values``."""
    out = bytearray()
    for source in sources:
        if source == CK_A:
            out.append(checksum(out[2:])[0])
        elif source == CK_B:
            out.append(checksum(out[2:-1])[1])
        elif isinstance(source, tuple):
            name, index = source
            out.append(values[name] >> (8 * index) & 0xFF)
        else:
            out.append(source)
    return bytes(out)


# --- NAV-PVT ------------------------------------------------------------------------------

#: NAV-PVT payload (M8, 92 bytes), in order: (name, struct format, loaded by the host).
#: Reserved bytes and the fields PX4 does not read and a rig has no source for (vehicle
#: heading, magnetic declination) are sent as zeros.
NAV_PVT_LAYOUT: tuple[tuple[str, str, bool], ...] = (
    ("iTOW", "I", True),  # GPS time of week [ms]
    ("year", "H", True),  # UTC
    ("month", "B", True),
    ("day", "B", True),
    ("hour", "B", True),
    ("min", "B", True),
    ("sec", "B", True),
    ("valid", "B", True),  # validDate 0x01, validTime 0x02, fullyResolved 0x04
    ("tAcc", "I", True),  # time accuracy [ns]
    ("nano", "i", True),  # fraction of second [ns]
    ("fixType", "B", True),  # 0 none, 2 2D, 3 3D
    ("flags", "B", True),  # gnssFixOK 0x01, diffSoln 0x02, carrSoln 0xC0
    ("flags2", "B", True),
    ("numSV", "B", True),
    ("lon", "i", True),  # [1e-7 deg]
    ("lat", "i", True),  # [1e-7 deg]
    ("height", "i", True),  # above ellipsoid [mm]
    ("hMSL", "i", True),  # above mean sea level [mm]
    ("hAcc", "I", True),  # [mm]
    ("vAcc", "I", True),  # [mm]
    ("velN", "i", True),  # [mm/s]
    ("velE", "i", True),
    ("velD", "i", True),
    ("gSpeed", "i", True),  # ground speed [mm/s]
    ("headMot", "i", True),  # heading of motion [1e-5 deg]
    ("sAcc", "I", True),  # speed accuracy [mm/s]
    ("headAcc", "I", True),  # heading accuracy [1e-5 deg]
    ("pDOP", "H", True),  # [0.01]
    ("reserved1", "6s", False),
    ("headVeh", "i", False),
    ("magDec", "h", False),
    ("magAcc", "H", False),
)
NAV_PVT_FORMAT = "<" + "".join(fmt for _, fmt, _ in NAV_PVT_LAYOUT)
NAV_PVT_LEN = struct.calcsize(NAV_PVT_FORMAT)
#: NAV-PVT valid: date, time and fully resolved (PX4 needs all three to take UTC time).
VALID_DATE_TIME_RESOLVED = 0x07
FLAGS_GNSS_FIX_OK = 0x01
FLAGS_DIFF_SOLN = 0x02

_SHAPES = {"B": unsigned(8), "H": unsigned(16), "I": unsigned(32), "i": signed(32)}


def _loaded() -> tuple[tuple[str, str], ...]:
    return tuple((name, fmt) for name, fmt, loaded in NAV_PVT_LAYOUT if loaded)


#: The fix the host loads (one field per loaded NAV-PVT field, each at most 32 bits).
SAMPLE_LAYOUT = data.StructLayout({name: _SHAPES[fmt] for name, fmt in _loaded()})


def _payload_sources() -> tuple[Source, ...]:
    out: list[Source] = []
    for name, fmt, loaded in NAV_PVT_LAYOUT:
        size = struct.calcsize("<" + fmt)
        out += [(name, i) for i in range(size)] if loaded else [0] * size
    return tuple(out)


NAV_PVT_SOURCES = frame_sources(CLASS_NAV, ID_NAV_PVT, _payload_sources())
assert len(NAV_PVT_SOURCES) == NAV_PVT_LEN + FRAME_OVERHEAD == 100


@dataclass(frozen=True)
class NavPvt:
    """The loaded NAV-PVT fields, in UBX units (see :data:`NAV_PVT_LAYOUT`)."""

    iTOW: int = 0
    year: int = 0
    month: int = 0
    day: int = 0
    hour: int = 0
    min: int = 0
    sec: int = 0
    valid: int = 0
    tAcc: int = 0
    nano: int = 0
    fixType: int = 0
    flags: int = 0
    flags2: int = 0
    numSV: int = 0
    lon: int = 0
    lat: int = 0
    height: int = 0
    hMSL: int = 0
    hAcc: int = 0
    vAcc: int = 0
    velN: int = 0
    velE: int = 0
    velD: int = 0
    gSpeed: int = 0
    headMot: int = 0
    sAcc: int = 0
    headAcc: int = 0
    pDOP: int = 0

    def __post_init__(self) -> None:
        for name, fmt in _loaded():
            value, shape = getattr(self, name), Shape.cast(_SHAPES[fmt])
            low = -(1 << (shape.width - 1)) if shape.signed else 0
            high = (1 << (shape.width - (1 if shape.signed else 0))) - 1
            if not low <= value <= high:
                raise ValueError(f"NAV-PVT {name}={value} outside {low}..{high}")

    def fields(self) -> dict[str, int]:
        """Field name to value, as the host port and :func:`render` take them."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def as_bits(self) -> int:
        """The fix packed as :data:`SAMPLE_LAYOUT` bits (for amaranth.sim)."""
        bits, offset = 0, 0
        for name, fmt in _loaded():
            width = Shape.cast(_SHAPES[fmt]).width
            bits |= (getattr(self, name) & ((1 << width) - 1)) << offset
            offset += width
        return bits

    def payload(self) -> bytes:
        """The 92-byte NAV-PVT payload."""
        values = [getattr(self, n) if loaded else 0 for n, _, loaded in NAV_PVT_LAYOUT]
        values[[n for n, _, _ in NAV_PVT_LAYOUT].index("reserved1")] = bytes(6)
        return struct.pack(NAV_PVT_FORMAT, *values)

    @classmethod
    def from_payload(cls, payload: bytes) -> NavPvt:
        """Inverse of :meth:`payload` (the fields a rig loads; the rest are ignored)."""
        if len(payload) != NAV_PVT_LEN:
            raise ValueError(f"NAV-PVT payload must be {NAV_PVT_LEN} bytes, not {len(payload)}")
        values = struct.unpack(NAV_PVT_FORMAT, payload)
        return cls(
            **{n: v for (n, _, loaded), v in zip(NAV_PVT_LAYOUT, values, strict=True) if loaded}
        )


def field_values(fix: NavPvt) -> dict[str, int]:
    """``fix`` as unsigned field words, the values :func:`render` reads bytes from."""
    return {name: getattr(fix, name) & 0xFFFFFFFF for name, _ in _loaded()}


# --- acknowledgements and MON-VER ---------------------------------------------------------

#: ACK-ACK / ACK-NAK carry the class and id of the acknowledged message.
ACK_SOURCES = frame_sources(CLASS_ACK, ID_ACK_ACK, (("ack_class", 0), ("ack_id", 0)))
NAK_SOURCES = frame_sources(CLASS_ACK, ID_ACK_NAK, (("ack_class", 0), ("ack_id", 0)))


def _text(value: str, size: int) -> bytes:
    return value.encode("ascii").ljust(size, b"\0")


#: MON-VER of a NEO-M8N, firmware SPG 3.01, protocol 18.00. PX4 reads hwVersion
#: "00080000" as u-blox 8, which selects its pre-protocol-27 configuration (CFG-PRT,
#: CFG-RATE, CFG-NAV5, CFG-MSG) and 115200 baud.
MON_VER_SW = "ROM CORE 3.01 (107888)"
MON_VER_HW = "00080000"
MON_VER_EXTENSIONS = ("FWVER=SPG 3.01", "PROTVER=18.00", "GPS;GLO;GAL;BDS", "SBAS;IMES;QZSS")
MON_VER_PAYLOAD = (
    _text(MON_VER_SW, 30)
    + _text(MON_VER_HW, 10)
    + b"".join(_text(extension, 30) for extension in MON_VER_EXTENSIONS)
)
MON_VER_SOURCES = frame_sources(CLASS_MON, ID_MON_VER, tuple(MON_VER_PAYLOAD))
