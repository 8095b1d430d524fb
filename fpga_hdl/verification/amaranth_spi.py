"""Pin-level SPI controller for ``amaranth.sim`` testbenches, implementing ``SpiBus``.

The fast unit tests drive the chip cores' pins with it, so the very driver code that
runs over cocotb and over the transaction-level bus also runs against ``amaranth.sim``.
Bits are driven from Python, one ``ctx.delay`` per half period: fine for unit tests,
never for the closed loop.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping
from typing import Protocol

from amaranth.hdl import Elaboratable, Signal
from amaranth.sim import Simulator, SimulatorContext

from fpga_hdl.buses.transactions import check_clock_hz, check_spi_mode, check_spi_request


class SpiPins(Protocol):
    """A chip's ``spi`` interface, the pins the controller drives and reads."""

    cs_n: Signal
    sclk: Signal
    mosi: Signal
    miso: Signal
    miso_oe: Signal


class AmaranthSpiController:
    """Drives ``sclk``/``cs_n``/``mosi`` of the SPI pins in ``devices`` (name → a chip's
    ``spi`` interface, :data:`~fpga_hdl.buses.signatures.SPI`); mode 0 or 3.

    ``cs_setup_s`` runs from CS falling to the first SCLK edge, ``cs_hold_s`` from the
    last SCLK edge to CS rising (PS-MPU-6000A-00 §6.8 t_SU.CS, t_HD.CS). An undriven SDO
    (``miso_oe`` low) reads as ``idle_level``, the pull-up.
    """

    def __init__(
        self,
        ctx: SimulatorContext,
        devices: Mapping[str, SpiPins],
        *,
        mode: int = 0,
        cs_setup_s: float = 50e-9,
        cs_hold_s: float = 500e-9,
        idle_level: int = 1,
    ) -> None:
        check_spi_mode(mode)
        self.ctx = ctx
        self.devices = dict(devices)
        self.mode = mode
        self.cs_setup_s = cs_setup_s
        self.cs_hold_s = cs_hold_s
        self.idle_level = idle_level

    async def idle(self) -> None:
        """Put every chip's pins in the idle state of the mode (CS high, SCLK = CPOL)."""
        for chip in self.devices.values():
            self.ctx.set(chip.cs_n, 1)
            self.ctx.set(chip.sclk, 1 if self.mode == 3 else 0)

    def _sample_miso(self, chip: SpiPins) -> int:
        return self.ctx.get(chip.miso) if self.ctx.get(chip.miso_oe) else self.idle_level

    async def transfer(self, device: str, tx: bytes, *, sclk_hz: float) -> bytes:
        check_clock_hz("sclk_hz", sclk_hz)
        check_spi_request(device, tx, self.devices)
        chip = self.devices[device]
        half_s = 0.5 / sclk_hz
        ctx = self.ctx
        ctx.set(chip.cs_n, 0)
        await ctx.delay(self.cs_setup_s)
        rx = bytearray()
        for byte in tx:
            value = 0
            for bit in range(7, -1, -1):
                if self.mode == 3:
                    ctx.set(chip.sclk, 0)
                ctx.set(chip.mosi, (byte >> bit) & 1)
                await ctx.delay(half_s)
                value = (value << 1) | self._sample_miso(chip)
                ctx.set(chip.sclk, 1)
                await ctx.delay(half_s)
                if self.mode == 0:
                    ctx.set(chip.sclk, 0)
            rx.append(value)
        await ctx.delay(self.cs_hold_s)
        ctx.set(chip.cs_n, 1)
        await ctx.delay(half_s)
        return bytes(rx)


def run_spi_testbench(
    dut: Elaboratable,
    *benches: Callable[[SimulatorContext], Awaitable[object]],
    sys_clk_hz: float,
    deadline_s: float | None = None,
) -> None:
    """Simulate ``dut`` with a ``sync`` clock and the given async testbenches.

    The first bench is the main one; the others run beside it (e.g. a host racing a
    bus read). With ``deadline_s`` the simulation stops there even if benches wait.
    """
    sim = Simulator(dut)
    sim.add_clock(1 / sys_clk_hz)
    for bench in benches:
        sim.add_testbench(bench, background=bench is not benches[0])
    if deadline_s is None:
        sim.run()
    else:
        sim.run_until(deadline_s)
