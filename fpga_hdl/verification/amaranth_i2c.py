"""Cycle-level I2C controller for ``amaranth.sim`` testbenches, implementing ``I2cBus``.

The counterpart of :mod:`fpga_hdl.verification.amaranth_spi`: unit tests drive a target's
pins with it, so PX4's drivers run over ``amaranth.sim`` unchanged. Every duration of a
:class:`~fpga_hdl.buses.i2c_target.I2cTiming` is rounded up to whole system cycles, and a
test may pass a timing beyond the specification to probe the target with illegal traffic.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from typing import Protocol

from amaranth.hdl import Elaboratable, Module, Signal
from amaranth.sim import Simulator, SimulatorContext

from fpga_hdl.buses.i2c_target import FAST_MODE, I2cTiming
from fpga_hdl.buses.transactions import combined_transfer

__all__ = ["AmaranthI2cController", "run_i2c_testbench"]


class I2cPins(Protocol):
    """A target's ``i2c`` interface: SCL and SDA in, its SDA pull-down out."""

    scl: Signal
    sda_i: Signal
    sda_oe: Signal


class AmaranthI2cController:
    """Drives ``scl`` and its side of SDA (``sda_ctrl``, 1 = released); reads ``sda_bus``,
    the wired-AND of every driver."""

    def __init__(
        self,
        ctx: SimulatorContext,
        scl: Signal,
        sda_ctrl: Signal,
        sda_bus: Signal,
        *,
        sys_clk_hz: float,
        timing: I2cTiming = FAST_MODE,
    ) -> None:
        self.ctx, self.scl, self.sda_ctrl, self.sda_bus = ctx, scl, sda_ctrl, sda_bus

        def cycles(ns: float) -> int:
            return math.ceil(ns * sys_clk_hz / 1e9)

        self.low = cycles(timing.t_low_ns)
        self.high = cycles(timing.t_high_ns)
        self.setup = cycles(timing.t_su_sta_ns)
        self.hold = cycles(timing.t_hd_sta_ns)
        self.buf = cycles(timing.t_buf_ns)

    async def wait(self, n: int) -> None:
        # One tick at a time, not ``tick().repeat(n)``: when an ``Assert`` stops the
        # simulation, amaranth 0.5 cannot close a pending ``repeat`` generator and warns.
        for _ in range(n):
            await self.ctx.tick()

    async def start(self) -> None:
        """START, or repeated START when SCL is low."""
        ctx = self.ctx
        if not ctx.get(self.scl):
            ctx.set(self.sda_ctrl, 1)
            await self.wait(self.low)
            ctx.set(self.scl, 1)
            await self.wait(self.setup)
        ctx.set(self.sda_ctrl, 0)
        await self.wait(self.hold)
        ctx.set(self.scl, 0)

    async def stop(self) -> None:
        ctx = self.ctx
        ctx.set(self.sda_ctrl, 0)
        await self.wait(self.low)
        ctx.set(self.scl, 1)
        await self.wait(self.setup)
        ctx.set(self.sda_ctrl, 1)
        await self.wait(self.buf)

    async def clock_bit(self, level: int) -> int:
        """One SCL pulse sending ``level`` (1 = release); returns SDA sampled while high."""
        ctx = self.ctx
        ctx.set(self.sda_ctrl, level)
        await self.wait(self.low)
        ctx.set(self.scl, 1)
        await self.wait(self.high)
        bit = ctx.get(self.sda_bus)
        ctx.set(self.scl, 0)
        return bit

    async def write_byte(self, byte: int) -> bool:
        for i in range(7, -1, -1):
            await self.clock_bit(byte >> i & 1)
        return await self.clock_bit(1) == 0

    async def read_byte(self, *, ack: bool) -> int:
        byte = 0
        for _ in range(8):
            byte = byte << 1 | await self.clock_bit(1)
        await self.clock_bit(0 if ack else 1)
        return byte

    async def write_read(
        self, address: int, write: bytes, read_len: int, *, scl_hz: float
    ) -> bytes:
        """``I2cBus``: the timing given at construction, whatever ``scl_hz`` asks."""
        return await combined_transfer(self, address, write, read_len)


def run_i2c_testbench(
    dut: Elaboratable,
    pins: I2cPins,
    bench: Callable[[SimulatorContext, AmaranthI2cController], Awaitable[object]],
    *,
    sys_clk_hz: float,
    timing: I2cTiming = FAST_MODE,
) -> object:
    """Simulate ``dut`` with its I2C ``pins`` on an open-drain bus; return ``bench``'s result.

    ``pins`` is the target's :data:`~fpga_hdl.buses.signatures.I2C` interface; ``bench``
    gets the testbench context and a controller once eight system cycles have passed.
    """
    m = Module()
    m.submodules.dut = dut
    scl, sda_ctrl, sda_bus = Signal(init=1), Signal(init=1), Signal()
    m.d.comb += [
        pins.scl.eq(scl),
        sda_bus.eq(sda_ctrl & ~pins.sda_oe),
        pins.sda_i.eq(sda_bus),
    ]
    sim = Simulator(m)
    sim.add_clock(1 / sys_clk_hz)
    result: dict[str, object] = {}

    async def testbench(ctx: SimulatorContext) -> None:
        await ctx.tick().repeat(8)
        controller = AmaranthI2cController(
            ctx, scl, sda_ctrl, sda_bus, sys_clk_hz=sys_clk_hz, timing=timing
        )
        result["value"] = await bench(ctx, controller)

    sim.add_testbench(testbench)
    sim.run()  # returns when the testbench does; the clock is a background process
    return result["value"]
