"""Transaction-level PWM capture: what ``core.py`` reports for given pulse trains.

Exact to the tick, including sampling and latency, so the tests can demand equality with
the RTL: clock edge ``k`` (at ``first_edge_s + k / tick_hz``) samples the input; an edge
landing exactly on a clock edge counts as already there. The core acts on a sample
``LATENCY_TICKS`` edges later; a reader behind a synchroniser sees it later still
(``latency_ticks``: SensorTop's host port reads ``fpga_hdl.top.PWM_RESULT_LATENCY_TICKS``).
"""

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

from fpga_hdl.chips.pwm_capture.core import CHANNELS, LATENCY_TICKS, timeout_ticks

__all__ = ["ChannelCapture", "PwmCaptureModel"]


class ChannelCapture(NamedTuple):
    """One channel's results, as the core's output registers hold them (a named tuple: the
    rig reads every motor's once a frame)."""

    width_ticks: int
    period_ticks: int
    timeout: bool


class PwmCaptureModel:
    """The core's arithmetic for one channel at a time, event by event (no per-tick loop).

    ``latency_ticks`` counts the clock edges from the one that samples an input edge to
    the results the reader sees: the core's own registers by default; more for a reader
    whose copy of them is that many edges younger (the whole result set moves as one, so
    the timeout runs from the delayed rise as well).
    """

    def __init__(
        self, *, tick_hz: float = 1e6, timeout_s: float = 0.1, latency_ticks: int = LATENCY_TICKS
    ) -> None:
        if not (isinstance(latency_ticks, int) and latency_ticks >= LATENCY_TICKS):
            raise ValueError(
                f"latency_ticks must be a whole number of ticks >= the core's {LATENCY_TICKS}, "
                f"not {latency_ticks!r}"
            )
        self.timeout_ticks = timeout_ticks(tick_hz, timeout_s)
        self.tick_hz = float(tick_hz)
        self.latency_ticks = latency_ticks

    def capture(
        self, pulses_s: Sequence[tuple[float, float]], *, at_s: float, first_edge_s: float = 0.0
    ) -> ChannelCapture:
        """Results visible just after the last clock edge at or before ``at_s``.

        ``pulses_s`` are (rise, fall) times in seconds, increasing; the line is low
        before the first rise and between pulses.
        """
        sampled = []
        previous_fall = -math.inf
        for rise_s, fall_s in pulses_s:
            if not previous_fall <= rise_s < fall_s:
                raise ValueError(
                    f"pulses must be increasing (rise < fall), got ({rise_s!r}, {fall_s!r}) "
                    f"after a fall at {previous_fall!r}"
                )
            previous_fall = fall_s
            sampled.append(self.sampled(rise_s, fall_s, first_edge_s))
        return self.capture_sampled(sampled, self.last_edge(at_s, first_edge_s))

    def sampled(self, rise_s: float, fall_s: float, first_edge_s: float = 0.0) -> tuple[int, int]:
        """The clock edges that first sample a pulse's rise and its fall (equal: a pulse
        between two samples, which the core never sees).

        In float seconds an edge is exact while the time keeps its tick: up to about 32 s
        at 1 MHz. A caller on a longer timeline computes the edges in integers and hands
        them to :meth:`capture_sampled` (the rig's ``PwmCapture`` does)."""
        return self._edge(rise_s, first_edge_s), self._edge(fall_s, first_edge_s)

    def last_edge(self, at_s: float, first_edge_s: float = 0.0) -> int:
        """Index of the last clock edge at or before ``at_s``."""
        return math.floor((at_s - first_edge_s) * self.tick_hz + 1e-9)

    def capture_sampled(self, sampled: Sequence[tuple[int, int]], now: int) -> ChannelCapture:
        """:meth:`capture` for pulses already turned into clock edges (:meth:`sampled`),
        read just after edge ``now``: a caller that keeps a pulse train samples each pulse
        once instead of at every read."""
        # One pass over the pulses, rise then fall, without building an event list: the
        # rig recomputes every motor's channel at each pulse end.
        latency, timeout_ticks = self.latency_ticks, self.timeout_ticks
        width = period = 0
        timeout, armed, last_rise = True, False, 0
        for rise_edge, fall_edge in sampled:
            if rise_edge == fall_edge:  # a pulse between two samples is never seen
                continue
            rise = rise_edge + latency
            if rise > now:
                break
            if armed and last_rise + timeout_ticks < rise:  # a rise on the deadline is in time
                armed, timeout, width, period = False, True, 0, 0
            if armed:
                period = rise - last_rise
            armed, last_rise = True, rise
            fall = fall_edge + latency
            if fall > now:
                break
            if last_rise + timeout_ticks <= fall:  # a fall on the deadline is too late
                armed, timeout, width, period = False, True, 0, 0
            else:
                width, timeout = fall - last_rise, False
        if armed and last_rise + timeout_ticks <= now:
            timeout, width, period = True, 0, 0
        return ChannelCapture(width, period, timeout)

    def _edge(self, time_s: float, first_edge_s: float) -> int:
        """Index of the first clock edge at or after ``time_s``."""
        return max(0, math.ceil((time_s - first_edge_s) * self.tick_hz - 1e-9))


#: The host-port keys of each channel's width and period, built once: a read per frame.
_CHANNEL_KEYS = tuple(
    (ch, ("pwm", f"width_ticks_{ch}"), ("pwm", f"period_ticks_{ch}")) for ch in range(CHANNELS)
)


def channel_captures(
    results: Mapping[tuple[str, str], int], channels: int = CHANNELS
) -> list[ChannelCapture]:
    """The PWM capture's results for the first ``channels`` out of the host port's result
    words (the cocotb and the compiled harness read the same words)."""
    timeout = results[("pwm", "timeout")]
    return [
        ChannelCapture(results[width], results[period], bool(timeout >> ch & 1))
        for ch, width, period in _CHANNEL_KEYS[:channels]
    ]
