"""Pin-level I2C controller for cocotb, implementing :class:`fpga_hdl.buses.transactions.I2cBus`.

It drives SCL and its side of the open-drain SDA the way a flight controller's I2C
peripheral does (UM10204 section 3.1), with every duration taken from an
:class:`~fpga_hdl.buses.i2c_target.I2cTiming`, so a test can put one field at the
specification's limit. It also checks the target: each bit the target sends must be
valid t_VD;DAT after SCL falls and stay stable until SCL falls again; a violation raises
:class:`I2cTimingViolation`.

Cost: the target oversamples the bus with the system clock, so that clock must run for
the whole transfer. The controller starts a cocotb :class:`~cocotb.clock.Clock` (C-level,
no Python per cycle) at the START and stops it after t_BUF, so an idle bus costs nothing.
The wired-AND is resolved here: ``sda_i = controller level AND NOT sda_oe``, updated on
every change of ``sda_oe`` (a few per byte).
"""

from __future__ import annotations

import cocotb
from cocotb.clock import Clock
from cocotb.handle import LogicObject
from cocotb.triggers import Timer
from cocotb.utils import get_sim_time

from fpga_hdl.buses.i2c_controller import timing_for
from fpga_hdl.buses.i2c_target import FAST_MODE, I2cTiming
from fpga_hdl.buses.transactions import combined_transfer

__all__ = ["CocotbI2cMaster", "I2cTimingViolation"]


class I2cTimingViolation(AssertionError):
    """The target's SDA was not valid, or not stable, when UM10204 requires it."""


def _ps(ns: float) -> int:
    return round(ns * 1000)


class CocotbI2cMaster:
    """I2C controller on ``scl``, ``sda_i`` (the target's view) and ``sda_oe`` (its drive).

    Parameters
    ----------
    scl, sda_i, sda_oe
        DUT handles: SCL input, SDA input (written with the resolved bus level), SDA
        pull-down enable of the target.
    clk
        The DUT's system clock, run only during transfers.
    sys_clk_hz
        Its frequency.
    timing
        Fixed timing for every transfer; ``None`` derives it from each call's ``scl_hz``.
    """

    def __init__(
        self,
        *,
        scl: LogicObject,
        sda_i: LogicObject,
        sda_oe: LogicObject,
        clk: LogicObject,
        sys_clk_hz: float,
        timing: I2cTiming | None = None,
    ) -> None:
        self.scl, self.sda_i, self.sda_oe, self.clk = scl, sda_i, sda_oe, clk
        self.sys_clk_hz = sys_clk_hz
        self.timing = timing
        self._level = 1  # the controller's own SDA: 1 = released
        # SCL as last driven. Kept here because a handle's value reads back the old level
        # until the simulator applies the write.
        self._scl = 1
        self._spike = 0  # 1 while an injected spike pulls SDA low
        self._clock: Clock | None = None
        self._clock_since_ps = 0.0
        #: System-clock cycles run for transfers so far: the bus's simulation cost.
        self.cycles = 0
        self._t = timing or FAST_MODE
        scl.value = 1
        sda_i.value = 1
        cocotb.start_soon(self._resolve())

    # --- bus level ---------------------------------------------------------------------

    def bus_sda(self) -> int:
        """The wired-AND of every SDA driver, as a pull-up resistor would make it."""
        return int(self._level and not self._spike and not int(self.sda_oe.value))

    def _update_sda(self) -> None:
        self.sda_i.value = self.bus_sda()

    async def _resolve(self) -> None:
        while True:
            await self.sda_oe.value_change
            self._update_sda()

    def _set_scl(self, level: int) -> None:
        self._scl = level
        self.scl.value = level

    def _set_sda(self, level: int) -> None:
        self._level = level
        self._update_sda()

    async def spike(self, line: str, width_ns: float) -> None:
        """Invert ``line`` ("scl" or "sda") for ``width_ns``: a glitch on the wire."""
        if line == "sda":
            self._spike = 1
            self._update_sda()
            await Timer(_ps(width_ns), unit="ps")
            self._spike = 0
            self._update_sda()
        elif line == "scl":
            self.scl.value = 1 - self._scl
            await Timer(_ps(width_ns), unit="ps")
            self.scl.value = self._scl
        else:
            raise ValueError(f"line must be 'scl' or 'sda', not {line!r}")

    async def _wait(self, ns: float) -> None:
        if ns > 0:
            await Timer(_ps(ns), unit="ps")

    # --- system clock ------------------------------------------------------------------

    def _clock_on(self) -> None:
        if self._clock is None:
            self._clock = Clock(self.clk, _ps(1e9 / self.sys_clk_hz), unit="ps")
            self._clock.start(start_high=False)
            self._clock_since_ps = get_sim_time("ps")

    async def _clock_off(self) -> None:
        """Stop the clock low and hold it there for half a period.

        A clock stopped while high would make the next caller's first rising edge no edge.
        """
        if self._clock is not None:
            self._clock.stop()
            self._clock = None
            elapsed_ps = get_sim_time("ps") - self._clock_since_ps
            self.cycles += round(elapsed_ps * self.sys_clk_hz / 1e12)
            self.clk.value = 0
            await Timer(_ps(0.5e9 / self.sys_clk_hz), unit="ps")

    # --- conditions and bits -----------------------------------------------------------

    async def start(self) -> None:
        """START from an idle bus, or repeated START when SCL is low."""
        t = self._t
        self._clock_on()
        if not self._scl:
            await self._wait(t.t_hd_dat_ns)
            self._set_sda(1)
            await self._wait(t.t_low_ns - t.t_hd_dat_ns)
            self._set_scl(1)
            await self._wait(t.t_su_sta_ns)
        self._set_sda(0)
        await self._wait(t.t_hd_sta_ns)
        self._set_scl(0)

    async def stop(self) -> None:
        """STOP, then t_BUF of free bus; the system clock stops after it."""
        t = self._t
        await self._wait(t.t_hd_dat_ns)
        self._set_sda(0)
        await self._wait(t.t_low_ns - t.t_hd_dat_ns)
        self._set_scl(1)
        await self._wait(t.t_su_sto_ns)
        self._set_sda(1)
        await self._wait(t.t_buf_ns)
        await self._clock_off()

    async def clock_bit(self, level: int, *, check: bool = False) -> int:
        """One SCL pulse with SDA ``level`` (1 = release); SDA as sampled while SCL is high.

        SDA changes t_HD;DAT after SCL fell and SCL rises no sooner than t_SU;DAT after
        that. With ``check``, the target's bit is sampled at t_VD;DAT, at t_SU;DAT before
        SCL rises and at the end of SCL high; all three must agree.
        """
        t = self._t
        await self._wait(t.t_hd_dat_ns)
        self._set_sda(level)
        low_rest_ns = max(t.t_low_ns - t.t_hd_dat_ns, t.t_su_dat_ns)
        samples = []
        if check:
            valid_ns = max(0.0, t.t_vd_dat_max_ns - t.t_hd_dat_ns)
            await self._wait(valid_ns)
            samples.append(self.bus_sda())
            await self._wait(low_rest_ns - valid_ns - t.t_su_dat_ns)
            samples.append(self.bus_sda())
            await self._wait(t.t_su_dat_ns)
        else:
            await self._wait(low_rest_ns)
        self._set_scl(1)
        await self._wait(t.t_high_ns / 2)
        bit = self.bus_sda()
        await self._wait(t.t_high_ns / 2)
        samples.append(self.bus_sda())
        self._set_scl(0)
        if check and len(set(samples)) != 1:
            raise I2cTimingViolation(
                f"target SDA not stable from t_VD;DAT to SCL falling: samples {samples}"
            )
        return bit

    async def write_byte(self, byte: int) -> bool:
        """Send ``byte``; True when the target ACKs."""
        for i in range(7, -1, -1):
            await self.clock_bit(byte >> i & 1)
        return await self.clock_bit(1, check=True) == 0

    async def read_byte(self, *, ack: bool) -> int:
        """Receive a byte, checking the target's data timing; then ACK or NACK it."""
        value = 0
        for _ in range(8):
            value = value << 1 | await self.clock_bit(1, check=True)
        await self.clock_bit(0 if ack else 1)
        return value

    def abandon(self) -> None:
        """A controller reset mid-transfer: both lines released, whatever the target does.

        The system clock keeps running (the target is still powered and clocked).
        """
        self._set_sda(1)
        self._set_scl(1)

    async def recover(self) -> int:
        """UM10204 3.1.16 bus clear: up to nine SCL pulses until SDA is free, then STOP.

        Returns the number of pulses it took; raises if SDA is still held after nine.
        """
        t = self._t
        self._clock_on()
        self._set_sda(1)
        pulses = 0
        while not self.bus_sda():
            if pulses == 9:
                await self._clock_off()
                raise I2cTimingViolation("SDA still held low after 9 recovery clocks")
            self._set_scl(0)
            await self._wait(t.t_low_ns)
            self._set_scl(1)
            await self._wait(t.t_high_ns)
            pulses += 1
        await self._wait(t.t_su_sta_ns)
        await self.start()  # START then STOP leaves every target idle
        await self.stop()
        return pulses

    # --- I2cBus ------------------------------------------------------------------------

    async def write_read(
        self, address: int, write: bytes, read_len: int, *, scl_hz: float
    ) -> bytes:
        """Write, repeated START, read (PX4 ``I2C::transfer``); raises :class:`I2cNack`."""
        self._t = self.timing or timing_for(scl_hz)
        return await combined_transfer(self, address, write, read_len)
