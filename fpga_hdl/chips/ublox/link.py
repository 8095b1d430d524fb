"""The GNSS path at transaction level: the receiver's solution, its faults, its UART twin.

For the rig's sensor layers (issue 18 item 4). A fix goes in as the receiver's solution
(:func:`receiver_solution`: loss of fix and jamming act there, as on a real receiver),
a bad checksum on the line (:data:`BAD_CHECKSUM_FLIP`, the core's ``fault.flip``), and
PX4's driver (:class:`~fpga_hdl.chips.ublox.driver.UbloxDriver`) reads it over a
:class:`~fpga_hdl.buses.transactions.UartPort`: the RTL's harness UART, or
:class:`TlmUbloxUart` here, the twin with the RTL's line time.
"""

from __future__ import annotations

from dataclasses import replace
from enum import StrEnum

from fpga_hdl.buses.transactions import UartTransfer
from fpga_hdl.buses.uart import cycles_to_us, divider_for, line_cycles
from fpga_hdl.chips.ublox.driver import GpsFix, nav_pvt_for_fix
from fpga_hdl.chips.ublox.model import UbloxM8Model
from fpga_hdl.chips.ublox.ubx import NavPvt

__all__ = ["BAD_CHECKSUM_FLIP", "GpsFault", "TlmUbloxUart", "receiver_solution"]

#: XOR mask on a frame's payload and checksum for :attr:`GpsFault.BAD_CHECKSUM`.
BAD_CHECKSUM_FLIP = 0x5A


class GpsFault(StrEnum):
    """Faults of the receiver or its line."""

    #: No solution: fixType 0, gnssFixOK clear, no satellites (PX4 sees fix_type 0).
    LOSS_OF_FIX = "loss_of_fix"
    #: Jammed: 3 satellites left, a 2D fix at best, accuracies 20x worse.
    JAMMED = "jammed"
    #: The frame arrives with a bad checksum and PX4 drops it.
    BAD_CHECKSUM = "bad_checksum"


def receiver_solution(fix: GpsFix, epoch_us: int, fault: GpsFault | None = None) -> NavPvt:
    """The NAV-PVT the receiver computes for ``fix`` measured at ``epoch_us`` (its iTOW),
    under ``fault``."""
    pvt = nav_pvt_for_fix(fix, itow_ms=epoch_us // 1000)
    if fault is GpsFault.LOSS_OF_FIX:
        return replace(pvt, fixType=0, flags=0, numSV=0)
    if fault is GpsFault.JAMMED:
        return replace(
            pvt,
            fixType=min(pvt.fixType, 2),
            numSV=min(pvt.numSV, 3),
            hAcc=min(pvt.hAcc * 20, 2**32 - 1),
            vAcc=min(pvt.vAcc * 20, 2**32 - 1),
        )
    return pvt


class TlmUbloxUart:
    """:class:`~fpga_hdl.buses.transactions.UartPort` over the twin: its bytes, with the line
    time the RTL's UART takes on its clock of ``clk_hz`` (SensorTop's ``UART_CLK_HZ``: the
    same divider, back-to-back bytes).

    A burst at a rate other than the receiver's is lost (a real receiver sees framing
    errors and answers nothing), so a handshake at the wrong rate fails here as on the RTL.
    """

    def __init__(self, model: UbloxM8Model, *, clk_hz: float) -> None:
        self.model = model
        self.clk_hz = clk_hz

    async def exchange(self, tx: bytes, *, baud: int) -> UartTransfer:
        if baud != self.model.baud:
            return UartTransfer(b"", 0)
        self.model.receive(tx)
        data = self.model.transmit()
        cycles = line_cycles(len(data), divider_for(self.clk_hz, baud))
        return UartTransfer(data, cycles_to_us(cycles, self.clk_hz))
