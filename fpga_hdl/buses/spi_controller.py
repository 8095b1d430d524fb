"""Autopilot-side SPI controller: the flight controller MCU's SPI peripheral, in gateware.

Why it exists: a bus master written in Python must wake up for every SCLK half period
(about 11 µs of wall time per edge under cocotb), so a 15-byte MPU-6000 burst cost
milliseconds. Here the whole transfer runs in the simulator: software loads the bytes,
asks once, and waits for one acknowledge, as a PX4 driver does with the MCU's SPI + DMA.

Behaviour, matching what the chips expect (PS-MPU-6000A-00 §6.8 and §9.5, MS5611-01BA03
"SPI mode"): modes 0 and 3 (CPOL = CPHA), MSB first; MOSI changes on the leading
(falling) edge of each bit and MISO is sampled on the rising edge; SCLK is the system
clock divided by ``2 * divider``, so a request is rounded *down* to the nearest rate the
divider can make, as an STM32 prescaler is; chip select falls ``cs_setup_s`` before the
first SCLK edge and rises ``cs_hold_s`` after the last one; the controller then waits
``cs_idle_s`` before it reports the transfer done, so back-to-back transfers keep the
chips' minimum deselect time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from amaranth.build import Platform
from amaranth.hdl import Cat, Module, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

__all__ = ["SpiController", "SpiControllerTiming", "divider_for"]

#: Largest SCLK divider (8-bit register): 16 MHz / 510 ≈ 31 kHz, below any chip's need.
DIVIDER_MAX = 255


@dataclass(frozen=True)
class SpiControllerTiming:
    """Chip-select timing the controller keeps, seconds; defaults meet PS-MPU-6000A-00 §6.8.

    The MS5611's SPI limits (datasheet "SPI timing") are looser, so the MPU-6000's
    minimums serve the whole shared bus.
    """

    cs_setup_s: float = 8e-9  # t_SU.CS: CS low to the first SCLK edge
    cs_hold_s: float = 500e-9  # t_HD.CS: last SCLK edge to CS high
    cs_idle_s: float = 100e-9  # CS high between two transfers

    def __post_init__(self) -> None:
        for name in ("cs_setup_s", "cs_hold_s", "cs_idle_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite duration >= 0 s, not {value!r}")


def cycles_covering(duration_s: float, clk_hz: float) -> int:
    """Whole clock cycles that cover ``duration_s`` (at least 1; float noise ignored)."""
    return max(1, math.ceil(duration_s * clk_hz - 1e-9))


def divider_for(sys_clk_hz: float, sclk_hz: float) -> int:
    """SCLK divider giving the fastest rate not above ``sclk_hz``; rejects unreachable rates."""
    divider = max(1, math.ceil(sys_clk_hz / (2 * sclk_hz) - 1e-9))
    if divider > DIVIDER_MAX:
        raise ValueError(
            f"sclk_hz {sclk_hz:g} is below the slowest SCLK of a {sys_clk_hz:g} Hz system "
            f"clock ({sys_clk_hz / (2 * DIVIDER_MAX):g} Hz)"
        )
    return divider


class SpiController(wiring.Component):
    """SPI controller with a byte buffer, one chip select per device, modes 0 and 3.

    Parameters
    ----------
    sys_clk_hz : float
        Frequency of the ``sync`` domain; timing is counted in its cycles.
    devices : int
        Number of chip-select lines.
    depth : int
        Buffer size in bytes: the longest transfer.
    timing : SpiControllerTiming
        Chip-select setup, hold and idle times.

    Attributes
    ----------
    request : In(1)
        Toggle to ask for a transfer (a request is pending while it differs from
        ``acknowledge``); the other inputs must hold until the acknowledge.
    acknowledge : Out(1)
        Set equal to ``request`` when the transfer (and ``cs_idle_s``) is over.
    busy : Out(1)
        A transfer is in progress.
    device : In(range(devices))
        Chip select to assert.
    length : In(range(depth + 1))
        Bytes to transfer.
    divider : In(8)
        SCLK half period in system cycles (1..255); see :func:`divider_for`.
    mode3 : In(1)
        1: mode 3 (SCLK idles high), 0: mode 0.
    tx : In(8 * depth)
        Bytes to send, byte ``i`` in bits ``8i .. 8i + 7``.
    rx : Out(8 * depth)
        Bytes received, same order; valid from the acknowledge to the next request.
    sclk, mosi : Out(1)
        Bus clock and controller data.
    miso : In(1)
        Target data (the bus pull-up makes an undriven line read 1).
    cs_n : Out(devices)
        Chip selects, active low.
    """

    def __init__(
        self,
        *,
        sys_clk_hz: float,
        devices: int,
        depth: int = 32,
        timing: SpiControllerTiming = SpiControllerTiming(),
    ) -> None:
        if not (math.isfinite(sys_clk_hz) and sys_clk_hz > 0):
            raise ValueError(f"sys_clk_hz must be a positive frequency in Hz, not {sys_clk_hz!r}")
        if not (isinstance(devices, int) and devices >= 1):
            raise ValueError(f"devices must be a positive integer, not {devices!r}")
        if not (isinstance(depth, int) and depth >= 1):
            raise ValueError(f"depth must be a positive integer, not {depth!r}")
        self.sys_clk_hz = float(sys_clk_hz)
        self.devices = devices
        self.depth = depth
        self.timing = timing
        self.cs_setup_cycles = cycles_covering(timing.cs_setup_s, sys_clk_hz)
        self.cs_hold_cycles = cycles_covering(timing.cs_hold_s, sys_clk_hz)
        self.cs_idle_cycles = cycles_covering(timing.cs_idle_s, sys_clk_hz)
        super().__init__(
            {
                "request": In(1),
                "acknowledge": Out(1),
                "busy": Out(1),
                "device": In(range(devices)),
                "length": In(range(depth + 1)),
                "divider": In(8),
                "mode3": In(1),
                "tx": In(8 * depth),
                "rx": Out(8 * depth),
                "sclk": Out(1),
                "mosi": Out(1),
                "miso": In(1),
                "cs_n": Out(devices, init=(1 << devices) - 1),
            }
        )

    def transfer_cycles(self, length: int, divider: int) -> int:
        """System cycles from the request to the acknowledge, for cycle budgets."""
        edges = 2 * divider * 8 * length
        return 2 + self.cs_setup_cycles + edges + self.cs_hold_cycles + self.cs_idle_cycles

    def elaborate(self, platform: Platform | None) -> Module:
        m = Module()
        wait = Signal(range(max(256, self.cs_hold_cycles + 1, self.cs_idle_cycles + 1)))
        shift = Signal(8 * self.depth)  # tx bytes out of the top, rx bits in at the bottom
        bytes_left = Signal(range(self.depth + 1))
        bit = Signal(range(8))
        device = Signal.like(self.device)
        divider = Signal(8)
        mode3 = Signal()
        unused = Signal(range(self.depth + 1))  # buffer bytes beyond the transfer
        top = 8 * self.depth - 1

        with m.FSM():
            with m.State("IDLE"), m.If(self.request != self.acknowledge):
                with m.If(self.length == 0):
                    m.d.sync += self.acknowledge.eq(self.request)
                with m.Else():
                    # Byte 0 goes first: reverse the byte order so the next bit to
                    # send is always the top bit of ``shift``.
                    reversed_tx = Cat(
                        *(self.tx[8 * i : 8 * i + 8] for i in reversed(range(self.depth)))
                    )
                    m.d.sync += [
                        shift.eq(reversed_tx),
                        bytes_left.eq(self.length),
                        unused.eq(self.depth - self.length),
                        device.eq(self.device),
                        divider.eq(self.divider),
                        mode3.eq(self.mode3),
                        self.sclk.eq(self.mode3),
                        bit.eq(7),
                    ]
                    m.next = "SELECT"
            with m.State("SELECT"):
                # SCLK took the mode's idle level a cycle before CS falls, so the chip
                # never sees an edge while it is being selected.
                m.d.comb += self.busy.eq(1)
                m.d.sync += [self.cs_n.eq(~(1 << device)), wait.eq(self.cs_setup_cycles - 1)]
                m.next = "SETUP"
            with m.State("SETUP"):
                m.d.comb += self.busy.eq(1)
                with m.If(wait == 0):
                    self._leading_edge(m, shift[top], divider, wait)
                    m.next = "LOW"
                with m.Else():
                    m.d.sync += wait.eq(wait - 1)
            with m.State("LOW"):  # SCLK low: the target shifts, MOSI holds
                m.d.comb += self.busy.eq(1)
                with m.If(wait == 0):
                    # Rising edge: the target samples MOSI; sample MISO now too.
                    m.d.sync += [
                        self.sclk.eq(1),
                        shift.eq(Cat(self.miso, shift[:top])),
                        wait.eq(divider - 1),
                    ]
                    m.next = "HIGH"
                with m.Else():
                    m.d.sync += wait.eq(wait - 1)
            with m.State("HIGH"):
                m.d.comb += self.busy.eq(1)
                last_bit = (bit == 0) & (bytes_left == 1)
                with m.If(wait == 0):
                    m.d.sync += bit.eq(bit - 1)
                    with m.If(bit == 0):
                        m.d.sync += bytes_left.eq(bytes_left - 1)
                    with m.If(last_bit):
                        m.d.sync += [self.sclk.eq(mode3), wait.eq(self.cs_hold_cycles - 1)]
                        m.next = "HOLD"
                    with m.Else():
                        self._leading_edge(m, shift[top], divider, wait)
                        m.next = "LOW"
                with m.Else():
                    m.d.sync += wait.eq(wait - 1)
            with m.State("HOLD"):
                m.d.comb += self.busy.eq(1)
                with m.If(wait == 0):
                    m.d.sync += [
                        self.cs_n.eq(self.cs_n.init),
                        wait.eq(self.cs_idle_cycles - 1),
                        # Received bytes, first byte at the bottom of ``rx``.
                        self.rx.eq(
                            Cat(*(shift[8 * i : 8 * i + 8] for i in reversed(range(self.depth))))
                            >> (unused * 8)
                        ),
                    ]
                    m.next = "IDLE_GAP"
                with m.Else():
                    m.d.sync += wait.eq(wait - 1)
            with m.State("IDLE_GAP"):
                m.d.comb += self.busy.eq(1)
                with m.If(wait == 0):
                    m.d.sync += self.acknowledge.eq(self.request)
                    m.next = "IDLE"
                with m.Else():
                    m.d.sync += wait.eq(wait - 1)
        return m

    def _leading_edge(self, m: Module, next_bit: Value, divider: Signal, wait: Signal) -> None:
        """SCLK falls (a no-op in mode 0 before the first bit) and MOSI takes the next bit."""
        m.d.sync += [self.sclk.eq(0), self.mosi.eq(next_bit), wait.eq(divider - 1)]
