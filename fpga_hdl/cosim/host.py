"""The rig's side of SensorTop's host port under cocotb, with a gated system clock.

The system clock runs only while the host port is written or a chip waits to take a
sample: :meth:`CocotbHost.cycles` toggles it from Python for a few cycles, so an idle
bus costs no simulation time (the clocks run only while a bus is active).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any  # a cocotb DUT: its ports, the generated Verilog's, are known at run time

from cocotb.triggers import Timer

from fpga_hdl.host.host_port import FaultInputs, HostPortMap

#: Cycles a chip may take to accept a sample after a transfer: synchroniser + copy.
SETTLE_CYCLES_MAX = 8


class HostPortTimeout(RuntimeError):
    """A chip never took its offered sample: ``pending`` stayed high."""


class CocotbHost:
    """Writes staged words, commits, and clocks SensorTop's ``sync`` domain on demand."""

    def __init__(self, dut: Any, host_map: HostPortMap, *, sys_clk_hz: float) -> None:
        self.dut = dut
        self.map = host_map
        self._half = Timer(round(0.5e12 / sys_clk_hz), unit="ps")
        self.cycles_run = 0  # system-clock cycles so far: the host's simulation cost

    async def cycles(self, count: int) -> None:
        """Run ``count`` cycles, each a low half then a rising edge and a high half.

        The rising edge comes half a period after the caller's writes: an input written in
        the time step of an edge is a race that the simulator decides (Icarus took the
        old value of ``commit`` once the design's logic was continuous assignments).
        """
        clk = self.dut.clk
        for _ in range(count):
            await self._half
            clk.value = 1
            await self._half
            clk.value = 0
        self.cycles_run += count

    async def reset(self) -> None:
        self.dut.clk.value = 0
        self.dut.rst.value = 1
        for name in ("write_en", "commit", "write_addr", "write_data", "read_addr"):
            getattr(self.dut, name).value = 0
        await self.cycles(2)
        self.dut.rst.value = 0
        await self.cycles(1)

    async def stage(
        self,
        samples: Mapping[str, Mapping[str, int]],
        *,
        now_us: int | None = None,
        faults: Mapping[str, FaultInputs] | None = None,
    ) -> None:
        """Write sample fields (and time, faults) into staging: invisible until commit."""
        words = self.map.encode_frame(samples, now_us=now_us, faults=faults)
        dut = self.dut
        dut.write_en.value = 1
        for address, data in words:
            dut.write_addr.value = address
            dut.write_data.value = data
            await self.cycles(1)
        dut.write_en.value = 0

    async def commit(self, *, settle: bool = True) -> None:
        """Publish everything staged in one cycle; with ``settle``, let the chips take it.

        With ``settle=False`` the clock stops right after the strobe reaches the chips
        (a test racing a transfer takes the sample in later with :meth:`settle`).
        """
        self.dut.commit.value = 1
        await self.cycles(1)
        self.dut.commit.value = 0
        await self.cycles(1)  # the strobe reaches the chips' latches
        if settle:
            await self.settle()

    async def load(
        self,
        samples: Mapping[str, Mapping[str, int]],
        *,
        now_us: int | None = None,
        faults: Mapping[str, FaultInputs] | None = None,
    ) -> None:
        """Stage, commit and settle: the usual way the rig updates the chips."""
        await self.stage(samples, now_us=now_us, faults=faults)
        await self.commit()

    async def settle(self) -> None:
        """Clock until no chip waits for a sample; free when none does."""
        for _ in range(SETTLE_CYCLES_MAX):
            if not int(self.dut.pending.value):
                return
            await self.cycles(1)
        raise HostPortTimeout(
            f"a chip still waits for its sample after {SETTLE_CYCLES_MAX} cycles; "
            "is a chip select stuck low?"
        )
