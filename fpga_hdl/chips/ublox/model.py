"""Transaction-level NEO-M8N: the UBX behaviour of ``core.py`` in plain Python.

It parses the autopilot's bytes with the core's state machine and renders the core's
frames from the same source tuples (:mod:`fpga_hdl.chips.ublox.ubx`), so its output is
byte-identical to the RTL's. Time is left out: :meth:`UbloxM8Model.transmit` returns
what the core sends next, in the core's order, at the rate :attr:`baud` names.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from fpga_hdl.chips.ublox import ubx
from fpga_hdl.chips.ublox.core import (
    BAUD_RATES,
    MIN_MEAS_RATE_MS,
    RESET_BAUD,
    RESET_MEAS_RATE_MS,
)
from fpga_hdl.chips.ublox.ubx import NavPvt

__all__ = ["UbloxM8Model"]

_NAV_PVT = bytes([ubx.CLASS_NAV, ubx.ID_NAV_PVT])
_SYNC1, _SYNC2, _CLASS, _ID, _LEN1, _LEN2, _PAYLOAD, _CKA, _CKB = range(9)


class UbloxM8Model:
    """One NEO-M8N on UART1; see :class:`~fpga_hdl.chips.ublox.core.UbloxM8Core`."""

    def __init__(self, *, baud: int = RESET_BAUD, nav_pvt_at_reset: bool = False) -> None:
        if baud not in BAUD_RATES:
            raise ValueError(f"baud must be one of {BAUD_RATES}, not {baud!r}")
        self.baud = baud
        self.nav_pvt_enabled = nav_pvt_at_reset
        #: CFG-RATE's measRate in force: fixes whose iTOW it divides are navigation epochs.
        self.meas_rate_ms = RESET_MEAS_RATE_MS
        #: Fault injection, as the core's ``fault.mute`` / ``fault.flip``.
        self.fault_mute = False
        self.fault_flip = 0
        self._fix = NavPvt()
        self._ack: tuple[bool, int, int] | None = None  # (ACK?, class, id)
        self._switch_to: int | None = None
        self._mon_ver = False
        self._pvt = False
        self._state = _SYNC1
        self._cls = self._id = self._len = 0
        self._payload = bytearray()
        self._ck = (0, 0)

    def load_fix(self, fix: NavPvt) -> None:
        """One measurement (the host port's ``sample_stb``); a navigation epoch when
        measRate divides its iTOW."""
        self._fix = fix
        if self.nav_pvt_enabled and fix.iTOW % self.meas_rate_ms == 0:
            self._pvt = True

    def receive(self, data: bytes) -> None:
        """Bytes from the autopilot, decoded as the core's parser does."""
        for byte in data:
            self._receive_byte(byte)

    def transmit(self) -> bytes:
        """Every frame now pending, in the core's order; applies a pending rate switch."""
        out = bytearray()
        while True:
            if self._ack is not None:
                is_ack, cls, msg_id = self._ack
                self._ack = None
                sources = ubx.ACK_SOURCES if is_ack else ubx.NAK_SOURCES
                out += self._send(sources, {"ack_class": cls, "ack_id": msg_id})
            elif self._switch_to is not None:
                self.baud, self._switch_to = self._switch_to, None
                break  # what follows is sent at the new rate: a separate call
            elif self._mon_ver:
                self._mon_ver = False
                out += self._send(ubx.MON_VER_SOURCES, {})
            elif self._pvt:
                self._pvt = False
                out += self._send(ubx.NAV_PVT_SOURCES, ubx.field_values(self._fix))
            else:
                break
        return bytes(out)

    def _send(self, sources: Sequence[ubx.Source], values: Mapping[str, int]) -> bytes:
        if self.fault_mute:
            return b""
        frame = ubx.render(sources, values)
        head = frame[: ubx.HEADER_LEN]
        return head + bytes(b ^ self.fault_flip for b in frame[ubx.HEADER_LEN :])

    def _receive_byte(self, byte: int) -> None:
        state = self._state
        if state == _SYNC1:
            self._state = _SYNC2 if byte == ubx.SYNC1 else _SYNC1
        elif state == _SYNC2:
            self._state = _CLASS if byte == ubx.SYNC2 else _SYNC1
            self._payload = bytearray()
        elif state in (_CLASS, _ID, _LEN1, _LEN2):
            if state == _CLASS:
                self._cls = byte
            elif state == _ID:
                self._id = byte
            elif state == _LEN1:
                self._len = byte
            else:
                self._len |= byte << 8
            self._state = state + 1 if state != _LEN2 or self._len else _CKA
        elif state == _PAYLOAD:
            self._payload.append(byte)
            if len(self._payload) == self._len:
                self._state = _CKA
        else:
            body = bytes([self._cls, self._id]) + self._len.to_bytes(2, "little") + self._payload
            ck_a, ck_b = ubx.checksum(body)
            if state == _CKA:
                self._state = _CKB if byte == ck_a else _SYNC1
            else:
                self._state = _SYNC1
                if byte == ck_b:
                    self._act()

    def _act(self) -> None:
        cls, msg_id, length, payload = self._cls, self._id, self._len, bytes(self._payload)
        if cls == ubx.CLASS_CFG:
            accepted = msg_id != ubx.ID_CFG_VALSET and length > 1
            if msg_id == ubx.ID_CFG_PRT and length >= ubx.CFG_PRT_BLOCK_LEN:
                if payload[0] == ubx.PORT_UART1:
                    offset = ubx.CFG_PRT_BAUD_OFFSET
                    rate = int.from_bytes(payload[offset : offset + 4], "little")
                    accepted = accepted and rate in BAUD_RATES
                    if accepted:
                        self._switch_to = rate
            elif msg_id == ubx.ID_CFG_MSG and length == 3 and payload[:2] == _NAV_PVT:
                self.nav_pvt_enabled = payload[2] != 0
            elif msg_id == ubx.ID_CFG_RATE:
                meas_rate = int.from_bytes(payload[:2], "little")
                accepted = accepted and length == ubx.CFG_RATE_LEN
                accepted = accepted and meas_rate >= MIN_MEAS_RATE_MS
                if accepted:
                    self.meas_rate_ms = meas_rate
            self._ack = (accepted, cls, msg_id)
        elif cls == ubx.CLASS_MON and msg_id == ubx.ID_MON_VER and length == 0:
            self._mon_ver = True
