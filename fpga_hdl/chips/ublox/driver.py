"""Autopilot-side u-blox model: PX4's UBX decoder and the configuration it sends an M8.

Written from PX4-GPSDrivers ``src/ubx.cpp``:

- :class:`UbxDecoder` is ``parseChar``: sync, class, id, length, payload, CK_A, CK_B; a
  frame with a bad checksum is dropped and counted.
- :func:`decode_nav_pvt` is ``payloadRxDone`` for NAV-PVT (units, ``fix_type`` rules).
- :func:`px4_configuration` lists what ``configure`` sends a receiver that NAKs
  CFG-VALSET and reports hardware "00080000" (u-blox 8) in MON-VER, with auto baud and
  the default settings: the pre-protocol-27 path (``configureDevicePreV27``).
- :class:`UbloxDriver` runs that handshake over a UART, checking each answer as
  ``configure`` does, then hands out each NAV-PVT once its last byte has arrived.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from fpga_hdl.buses.transactions import BusError, UartPort
from fpga_hdl.chips.ublox import ubx
from fpga_hdl.chips.ublox.ubx import NavPvt

__all__ = [
    "PX4_BAUD_RATES",
    "ConfigStep",
    "GpsFix",
    "ReceivedFix",
    "UbloxDriver",
    "UbloxHandshakeError",
    "UbxDecoder",
    "UbxFrame",
    "decode_nav_pvt",
    "nav_pvt_for_fix",
    "px4_configuration",
]

#: The rates ``configure`` tries, in its order.
PX4_BAUD_RATES = (38400, 57600, 9600, 115200, 230400, 460800, 921600)
#: ``UBX_TX_CFG_PRT_BAUDRATE``: the first switch with auto baud; then M8 and newer go to
#: ``UBX_BAUDRATE_M8_AND_NEWER``.
PX4_FIRST_BAUD = 38400
PX4_M8_BAUD = 115200
#: ``UBX_TX_CFG_RATE_MEASINTERVAL``: 200 ms, 5 Hz on the pre-27 path.
PX4_MEAS_RATE_MS = 200
#: ``UBX_TX_CFG_PRT_MODE`` (8N1) and the protocol masks for ``OutputMode::GPS``.
_PRT_MODE_8N1 = 0x000008D0
_PROTO_UBX, _PROTO_RTCM = 0x01, 0x20
_PORT_USB = 0x03
#: PX4 default dynamic model (``GPS_UBX_DYNMODEL`` 7, airborne < 2 g) and 3D-only fix.
_DYN_MODEL, _FIX_MODE_3D, _NAV5_MASK = 7, 2, 0x0005


@dataclass(frozen=True)
class UbxFrame:
    """One decoded frame with a valid checksum."""

    cls: int
    msg_id: int
    payload: bytes


class UbxDecoder:
    """PX4's ``parseChar`` state machine; :meth:`feed` returns the frames completed."""

    def __init__(self) -> None:
        self.checksum_errors = 0
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[UbxFrame]:
        """Decode ``data``; frames with a bad checksum are dropped and counted."""
        frames = []
        for byte in data:
            frame = self._byte(byte)
            if frame is not None:
                frames.append(frame)
        return frames

    def _byte(self, byte: int) -> UbxFrame | None:
        buf = self._buffer
        buf.append(byte)
        if len(buf) == 1:
            if byte != ubx.SYNC1:
                buf.clear()
            return None
        if len(buf) == 2:
            if byte != ubx.SYNC2:
                buf.clear()
            return None
        if len(buf) < 6:
            return None
        length = int.from_bytes(buf[4:6], "little")
        if len(buf) < length + ubx.FRAME_OVERHEAD:
            ck_a_at = length + 6
            if len(buf) == ck_a_at + 1 and byte != ubx.checksum(buf[2:ck_a_at])[0]:
                self.checksum_errors += 1
                buf.clear()
            return None
        body, (_, ck_b) = bytes(buf[2:-2]), buf[-2:]
        buf.clear()
        if ck_b != ubx.checksum(body)[1]:
            self.checksum_errors += 1
            return None
        return UbxFrame(body[0], body[1], body[4:])


@dataclass(frozen=True)
class GpsFix:
    """What PX4 takes from one NAV-PVT into ``sensor_gps`` (SI units, PX4's names)."""

    fix_type: int
    satellites_used: int
    latitude_deg: float
    longitude_deg: float
    altitude_msl_m: float
    altitude_ellipsoid_m: float
    eph: float
    epv: float
    vel_n_m_s: float
    vel_e_m_s: float
    vel_d_m_s: float
    vel_m_s: float
    cog_rad: float
    s_variance_m_s: float
    c_variance_rad: float
    vel_ned_valid: bool


def decode_nav_pvt(payload: bytes) -> GpsFix:
    """PX4 ``payloadRxDone`` for NAV-PVT: fix type from flags, then the unit changes."""
    pvt = NavPvt.from_payload(payload)
    fix_ok = pvt.flags & ubx.FLAGS_GNSS_FIX_OK
    fix_type = pvt.fixType if fix_ok else 0
    if fix_ok and pvt.flags & ubx.FLAGS_DIFF_SOLN:
        fix_type = 4
    if fix_ok and pvt.flags >> 6 in (1, 2):
        fix_type = 4 + (pvt.flags >> 6)
    deg_e5 = math.radians(1) * 1e-5
    return GpsFix(
        fix_type=fix_type,
        satellites_used=pvt.numSV,
        latitude_deg=pvt.lat * 1e-7,
        longitude_deg=pvt.lon * 1e-7,
        altitude_msl_m=pvt.hMSL * 1e-3,
        altitude_ellipsoid_m=pvt.height * 1e-3,
        eph=pvt.hAcc * 1e-3,
        epv=pvt.vAcc * 1e-3,
        vel_n_m_s=pvt.velN * 1e-3,
        vel_e_m_s=pvt.velE * 1e-3,
        vel_d_m_s=pvt.velD * 1e-3,
        vel_m_s=pvt.gSpeed * 1e-3,
        cog_rad=pvt.headMot * deg_e5,
        s_variance_m_s=pvt.sAcc * 1e-3,
        c_variance_rad=pvt.headAcc * deg_e5,
        vel_ned_valid=bool(fix_ok),
    )


def nav_pvt_for_fix(fix: GpsFix, *, itow_ms: int = 0, num_dop_e2: int = 120) -> NavPvt:
    """The NAV-PVT a receiver reports for ``fix`` (the rig's side of the round trip)."""
    flags = ubx.FLAGS_GNSS_FIX_OK if fix.fix_type >= 2 else 0
    deg_e5 = math.degrees(1) * 1e5
    return NavPvt(
        iTOW=itow_ms % (7 * 86_400_000),
        fixType=min(fix.fix_type, 3),
        flags=flags,
        numSV=fix.satellites_used,
        lat=round(fix.latitude_deg * 1e7),
        lon=round(fix.longitude_deg * 1e7),
        hMSL=round(fix.altitude_msl_m * 1e3),
        height=round(fix.altitude_ellipsoid_m * 1e3),
        hAcc=round(fix.eph * 1e3),
        vAcc=round(fix.epv * 1e3),
        velN=round(fix.vel_n_m_s * 1e3),
        velE=round(fix.vel_e_m_s * 1e3),
        velD=round(fix.vel_d_m_s * 1e3),
        gSpeed=round(fix.vel_m_s * 1e3),
        headMot=round(fix.cog_rad * deg_e5),
        sAcc=round(fix.s_variance_m_s * 1e3),
        headAcc=round(fix.c_variance_rad * deg_e5),
        pDOP=num_dop_e2,
    )


@dataclass(frozen=True)
class ConfigStep:
    """One frame PX4 sends, at ``baud``, and what it then waits for."""

    baud: int
    frame: bytes
    expect: str  # "ack", "nak", "ack-or-nothing" (PX4 reads but does not need it), "mon-ver"
    then_baud: int | None = None  # PX4 switches its own UART after this step


def _cfg_prt(baud: int) -> bytes:
    block = struct.pack(
        "<BBHIIHHHH",
        ubx.PORT_UART1,
        0,
        0,
        _PRT_MODE_8N1,
        baud,
        _PROTO_UBX | _PROTO_RTCM,
        _PROTO_UBX,
        0,
        0,
    )
    usb = bytes([_PORT_USB]) + block[1:]
    return ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_PRT, block + usb)


def _cfg_msg(cls: int, msg_id: int, rate: int) -> bytes:
    return ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_MSG, bytes([cls, msg_id, rate]))


def px4_configuration(receiver_baud: int = 9600) -> list[ConfigStep]:
    """PX4's frames for an M8 listening at ``receiver_baud``, from the rate it finds the
    receiver at: CFG-VALSET (NAKed), CFG-PRT at that rate, CFG-PRT to 38400, MON-VER,
    CFG-PRT to 115200, then CFG-RATE, CFG-NAV5 and CFG-MSG for NAV-PVT, NAV-STATUS,
    NAV-DOP, NAV-SVINFO and MON-HW (PX4 requires each ACK)."""
    valset_payload = bytes([0, 0x01, 0, 0]) + struct.pack("<IB", 0x20520002, 1)  # UART1 stop bits
    steps = [
        ConfigStep(
            receiver_baud, ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_VALSET, valset_payload), "nak"
        ),
        ConfigStep(receiver_baud, _cfg_prt(receiver_baud), "ack"),
        ConfigStep(receiver_baud, _cfg_prt(PX4_FIRST_BAUD), "ack-or-nothing", PX4_FIRST_BAUD),
        ConfigStep(PX4_FIRST_BAUD, ubx.frame(ubx.CLASS_MON, ubx.ID_MON_VER), "mon-ver"),
        ConfigStep(PX4_FIRST_BAUD, _cfg_prt(PX4_M8_BAUD), "ack-or-nothing", PX4_M8_BAUD),
    ]
    rate = struct.pack("<HHH", PX4_MEAS_RATE_MS, 1, 0)
    nav5 = struct.pack("<HBB", _NAV5_MASK, _DYN_MODEL, _FIX_MODE_3D) + bytes(32)
    frames = [
        ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_RATE, rate),
        ubx.frame(ubx.CLASS_CFG, ubx.ID_CFG_NAV5, nav5),
        _cfg_msg(ubx.CLASS_NAV, ubx.ID_NAV_PVT, 1),
        _cfg_msg(ubx.CLASS_NAV, ubx.ID_NAV_STATUS, 1),
        _cfg_msg(ubx.CLASS_NAV, ubx.ID_NAV_DOP, 1),
        _cfg_msg(ubx.CLASS_NAV, ubx.ID_NAV_SVINFO, 0),  # 5 when satellite info is wanted
        _cfg_msg(ubx.CLASS_MON, ubx.ID_MON_HW, 1),
    ]
    steps += [ConfigStep(PX4_M8_BAUD, frame, "ack") for frame in frames]
    return steps


class UbloxHandshakeError(BusError):
    """The receiver did not answer PX4's configuration as a u-blox 8 must."""


@dataclass(frozen=True)
class ReceivedFix:
    """A fix as PX4's driver has it: its NAV-PVT left the receiver at ``sent_us`` and its
    last byte was in the autopilot's UART at ``time_us``."""

    time_us: int
    sent_us: int
    fix: GpsFix


class UbloxDriver:
    """PX4's u-blox driver on a UART: the configuration handshake, then NAV-PVT in.

    :meth:`configure` sends :func:`px4_configuration` step by step at each step's rate and
    checks the answer PX4 waits for (ACK-ACK or ACK-NAK naming the message, MON-VER of a
    u-blox 8); a missing or wrong answer is a :class:`UbloxHandshakeError`. After each
    navigation epoch :meth:`receive` collects the receiver's bytes; :meth:`poll` hands out
    the fixes whose last byte has arrived by then, oldest first.
    """

    def __init__(self, uart: UartPort, *, receiver_baud: int = 9600) -> None:
        self.uart = uart
        self.baud = receiver_baud
        self.decoder = UbxDecoder()
        self._in_flight: list[ReceivedFix] = []

    async def configure(self) -> None:
        for step in px4_configuration(self.baud):
            transfer = await self.uart.exchange(step.frame, baud=step.baud)
            _check_answer(step, self.decoder.feed(transfer.data))
            if step.then_baud is not None:
                self.baud = step.then_baud

    async def receive(self, now_us: int) -> None:
        """Read what the receiver sends for the epoch it was given at ``now_us``."""
        transfer = await self.uart.exchange(b"", baud=self.baud)
        for frame in self.decoder.feed(transfer.data):
            if (frame.cls, frame.msg_id) == (ubx.CLASS_NAV, ubx.ID_NAV_PVT):
                fix = decode_nav_pvt(frame.payload)
                self._in_flight.append(ReceivedFix(now_us + transfer.line_us, now_us, fix))

    def poll(self, now_us: int) -> tuple[ReceivedFix, ...]:
        """The fixes whose last byte has arrived by ``now_us``, oldest first."""
        if not self._in_flight or self._in_flight[0].time_us > now_us:
            return ()
        arrived = tuple(f for f in self._in_flight if f.time_us <= now_us)
        self._in_flight = [f for f in self._in_flight if f.time_us > now_us]
        return arrived


def _check_answer(step: ConfigStep, frames: list[UbxFrame]) -> None:
    """Raise unless ``frames`` hold the answer ``step`` waits for (PX4 ``waitForAck``)."""
    if step.expect == "ack-or-nothing":
        return
    asked = (step.frame[2], step.frame[3])
    found = [(f.cls, f.msg_id, f.payload) for f in frames]
    if step.expect == "mon-ver":
        for cls, msg_id, payload in found:
            if (cls, msg_id) == (ubx.CLASS_MON, ubx.ID_MON_VER):
                hardware = payload[30:40].rstrip(b"\0").decode("ascii", "replace")
                if hardware == ubx.MON_VER_HW:
                    return
                raise UbloxHandshakeError(f"MON-VER reports hardware {hardware!r}, not a u-blox 8")
        raise UbloxHandshakeError("no MON-VER answer to PX4's poll")
    wanted = ubx.ID_ACK_ACK if step.expect == "ack" else ubx.ID_ACK_NAK
    if (ubx.CLASS_ACK, wanted, bytes(asked)) not in found:
        name = "ACK-ACK" if step.expect == "ack" else "ACK-NAK"
        raise UbloxHandshakeError(
            f"no {name} for message 0x{asked[0]:02X} 0x{asked[1]:02X} at {step.baud} baud "
            f"(received {len(frames)} frame(s))"
        )
