"""PWM pulse trains on a cocotb pin vector: the autopilot's motor outputs, edge by edge.

Each channel is its own coroutine that sleeps from edge to edge (two Python wake-ups per
pulse, none per clock cycle). Channels share one vector port, so every write carries
the current level of all channels.
"""

from __future__ import annotations

from cocotb.handle import LogicArrayObject
from cocotb.triggers import Timer

__all__ = ["CocotbPwmSource"]


def _ps(seconds: float) -> int:
    return round(seconds * 1e12)


class CocotbPwmSource:
    """Drives ``pins`` (one bit per channel); all channels start low."""

    def __init__(self, pins: LogicArrayObject, channels: int = 8) -> None:
        self.pins = pins
        self.channels = channels
        self._levels = 0
        pins.value = 0

    def _set(self, channel: int, level: int) -> None:
        if level:
            self._levels |= 1 << channel
        else:
            self._levels &= ~(1 << channel)
        self.pins.value = self._levels

    async def pulses(
        self, channel: int, *, width_s: float, period_s: float, count: int, start_s: float = 0.0
    ) -> None:
        """``count`` pulses of ``width_s`` every ``period_s``, the first at ``start_s`` from now.

        Edge times are rounded to whole picoseconds from the train's start, so long
        trains do not drift.
        """
        if not 0 <= channel < self.channels:
            raise ValueError(f"channel must be in 0..{self.channels - 1}, not {channel!r}")
        if not 0 < width_s < period_s:
            raise ValueError(
                f"PWM needs 0 < width_s < period_s, got width_s={width_s!r}, period_s={period_s!r}"
            )
        elapsed_ps = 0
        for index in range(count):
            for level, at_s in (
                (1, start_s + index * period_s),
                (0, start_s + index * period_s + width_s),
            ):
                wait_ps = _ps(at_s) - elapsed_ps
                if wait_ps > 0:
                    await Timer(wait_ps, unit="ps")
                elapsed_ps += max(wait_ps, 0)
                self._set(channel, level)
