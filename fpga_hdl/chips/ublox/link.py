"""The GNSS path at transaction level: a fix into the receiver twin, out of PX4's decoder.

For the rig's sensor layers (issue 18 item 4): :class:`UbxGpsLink` configures the twin
with PX4's handshake, turns each epoch's fix into NAV-PVT bytes, and hands back what
PX4's decoder makes of them, once the last byte has crossed the UART. Faults are applied
where they happen on a real receiver: loss of fix and jamming in the receiver's solution,
a corrupted frame on the line.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

from fpga_hdl.buses.uart import divider_for
from fpga_hdl.chips.ublox.driver import (
    GpsFix,
    UbxDecoder,
    decode_nav_pvt,
    nav_pvt_for_fix,
    px4_configuration,
)
from fpga_hdl.chips.ublox.model import UbloxM8Model
from fpga_hdl.chips.ublox.ubx import CLASS_NAV, ID_NAV_PVT

__all__ = ["GpsFault", "UbxGpsLink"]

#: Bits per byte on an 8N1 line.
_BITS_PER_BYTE = 10


class GpsFault(enum.Enum):
    """Faults of the receiver or its line."""

    #: No solution: fixType 0, gnssFixOK clear, no satellites (PX4 sees fix_type 0).
    LOSS_OF_FIX = "loss_of_fix"
    #: Jammed: 3 satellites left, a 2D fix at best, accuracies 20x worse.
    JAMMED = "jammed"
    #: The frame arrives with a bad checksum and PX4 drops it.
    BAD_CHECKSUM = "bad_checksum"


@dataclass(frozen=True)
class _InFlight:
    arrives_us: int
    frame: bytes


class UbxGpsLink:
    """Receiver twin, UART timing and PX4's decoder, back to back.

    Parameters
    ----------
    sys_clk_hz : float
        The core's clock; the UART time uses its real divider, as the RTL does.
    nav_latency_us : int
        From the epoch to the first byte on the line (the receiver's solution time).
    """

    def __init__(self, *, sys_clk_hz: float, nav_latency_us: int = 0) -> None:
        self.model = UbloxM8Model()
        self.decoder = UbxDecoder()
        for step in px4_configuration(self.model.baud):
            self.model.receive(step.frame)
            self.model.transmit()
        self.sys_clk_hz = sys_clk_hz
        self.nav_latency_us = nav_latency_us
        self._in_flight: list[_InFlight] = []
        self._line_free_us = 0

    @property
    def baud(self) -> int:
        """UART1's rate after PX4's configuration (115200 for an M8)."""
        return self.model.baud

    def byte_time_us(self) -> float:
        """One 8N1 byte at the configured rate, with the core's divider."""
        divider = divider_for(self.sys_clk_hz, self.baud)
        return _BITS_PER_BYTE * divider / self.sys_clk_hz * 1e6

    def epoch(self, fix: GpsFix, now_us: int, fault: GpsFault | None = None) -> None:
        """One navigation epoch at ``now_us``: the receiver reports ``fix``."""
        pvt = nav_pvt_for_fix(fix, itow_ms=now_us // 1000)
        if fault is GpsFault.LOSS_OF_FIX:
            pvt = replace(pvt, fixType=0, flags=0, numSV=0)
        elif fault is GpsFault.JAMMED:
            pvt = replace(
                pvt,
                fixType=min(pvt.fixType, 2),
                numSV=min(pvt.numSV, 3),
                hAcc=min(pvt.hAcc * 20, 2**32 - 1),
                vAcc=min(pvt.vAcc * 20, 2**32 - 1),
            )
        self.model.fault_flip = 0x5A if fault is GpsFault.BAD_CHECKSUM else 0
        self.model.load_fix(pvt)
        frame = self.model.transmit()
        start_us = max(now_us + self.nav_latency_us, self._line_free_us)
        arrives_us = round(start_us + len(frame) * self.byte_time_us())
        self._line_free_us = arrives_us
        self._in_flight.append(_InFlight(arrives_us, frame))

    def poll(self, now_us: int) -> list[GpsFix]:
        """The fixes PX4 has decoded by ``now_us``, oldest first."""
        arrived = [f for f in self._in_flight if f.arrives_us <= now_us]
        self._in_flight = [f for f in self._in_flight if f.arrives_us > now_us]
        fixes = []
        for flight in arrived:
            for frame in self.decoder.feed(flight.frame):
                if (frame.cls, frame.msg_id) == (CLASS_NAV, ID_NAV_PVT):
                    fixes.append(decode_nav_pvt(frame.payload))
        return fixes
