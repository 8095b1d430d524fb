"""Pin-level SPI controller for cocotb, implementing :class:`fpga_hdl.buses.transactions.SpiBus`.

It drives SensorTop's shared SPI pins the way a flight controller's SPI peripheral
does: chip select low, ``cs_setup_s``, eight SCLK periods per byte (MOSI changes on the
leading edge of each bit, MISO is sampled on the rising edge), ``cs_hold_s`` after the
last edge, chip select high. Mode 0 idles SCLK low, mode 3 high. Timing is a frozen
dataclass so a test can set one field to a datasheet limit.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass

from cocotb.handle import LogicObject
from cocotb.triggers import Timer

from fpga_hdl.buses.transactions import check_clock_hz, check_spi_mode, check_spi_request


@dataclass(frozen=True)
class SpiMasterTiming:
    """Controller-side SPI timing, seconds; defaults meet PS-MPU-6000A-00 §6.8."""

    mode: int = 0
    cs_setup_s: float = 8e-9  # t_SU.CS minimum
    cs_hold_s: float = 500e-9  # t_HD.CS minimum
    cs_idle_s: float = 100e-9  # CS high between two transfers
    idle_level: int = 1  # an undriven MISO reads as the pull-up

    def __post_init__(self) -> None:
        check_spi_mode(self.mode)
        for name in ("cs_setup_s", "cs_hold_s", "cs_idle_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, not {getattr(self, name)!r}")


DEFAULT_TIMING = SpiMasterTiming()


def _ps(seconds: float) -> int:
    return round(seconds * 1e12)


class CocotbSpiMaster:
    """SPI controller on ``sclk``/``mosi``/``miso``/``miso_oe`` and one CS per device.

    ``after_release`` runs after each chip-select release (SensorTop's harness uses it
    to clock a deferred sample copy in).
    """

    def __init__(
        self,
        *,
        sclk: LogicObject,
        mosi: LogicObject,
        miso: LogicObject,
        miso_oe: LogicObject,
        chip_selects: Mapping[str, LogicObject],
        timing: SpiMasterTiming = DEFAULT_TIMING,
        after_release: Callable[[], Awaitable[None]] | None = None,
    ) -> None:
        self.sclk, self.mosi, self.miso, self.miso_oe = sclk, mosi, miso, miso_oe
        self.chip_selects = dict(chip_selects)
        self.timing = timing
        self.after_release = after_release
        self.edges = 0  # SCLK edges driven so far: the bus's simulation cost

    def idle(self) -> None:
        for cs_n in self.chip_selects.values():
            cs_n.value = 1
        self.sclk.value = 1 if self.timing.mode == 3 else 0
        self.mosi.value = 0

    def _read_miso(self) -> int:
        return int(self.miso.value) if int(self.miso_oe.value) else self.timing.idle_level

    async def transfer(
        self, device: str, tx: bytes, *, sclk_hz: float, gaps_s: Sequence[float] = ()
    ) -> bytes:
        """One chip select over ``tx``; ``gaps_s[i]`` holds SCLK idle that much longer
        between byte ``i`` and byte ``i + 1`` (a chip's inter-byte delays, e.g. the
        PMW3901's t_SRAD between a read's address and its data)."""
        check_clock_hz("sclk_hz", sclk_hz)
        check_spi_request(device, tx, self.chip_selects)
        if len(gaps_s) >= max(len(tx), 1) or any(gap < 0 for gap in gaps_s):
            raise ValueError(f"{len(gaps_s)} gaps for {len(tx)} bytes; each must be >= 0")
        cs_n = self.chip_selects[device]
        timing, half = self.timing, Timer(_ps(0.5 / sclk_hz), unit="ps")
        mode3 = timing.mode == 3
        cs_n.value = 0
        if timing.cs_setup_s:
            await Timer(_ps(timing.cs_setup_s), unit="ps")
        rx = bytearray()
        for index, byte in enumerate(tx):
            if 0 < index <= len(gaps_s) and gaps_s[index - 1]:
                await Timer(_ps(gaps_s[index - 1]), unit="ps")
            value = 0
            for bit in range(7, -1, -1):
                if mode3:
                    self.sclk.value = 0
                self.mosi.value = (byte >> bit) & 1
                await half
                value = (value << 1) | self._read_miso()
                self.sclk.value = 1
                await half
                if not mode3:
                    self.sclk.value = 0
            rx.append(value)
        self.edges += 16 * len(tx)
        if timing.cs_hold_s:
            await Timer(_ps(timing.cs_hold_s), unit="ps")
        cs_n.value = 1
        if timing.cs_idle_s:
            await Timer(_ps(timing.cs_idle_s), unit="ps")
        if self.after_release is not None:
            await self.after_release()
        return bytes(rx)
