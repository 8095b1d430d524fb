"""Actuator controls → PWM pulses on the autopilot's outputs → what the ESCs receive.

The autopilot side (:class:`PwmOutput`) behaves as PX4's ``pwm_out`` with its default
output functions: every ``1/pwm_hz`` a pulse starts whose width was latched from the
latest actuator controls, mapped linearly from 0..1 onto the motor outputs' range
(``PWM_MAIN_MIN``/``MAX``, PX4's defaults 1000..2000 µs; a real airframe often has e.g.
1100..1900 µs, so the armed motors idle at command 0), 1000 µs (``PWM_MAIN_DIS``) while
disarmed. So a new command reaches the motors only at the
next PWM period (up to 2.5 ms later at 400 Hz), as on the real rig. A dropped-out channel
emits no pulse at all. The pulses go to the PWM capture core (RTL) or its model (TLM), and
the captured widths, not the commands, drive the motors; a channel whose capture timed out
means zero thrust (the ESC's failsafe). Motor ``i`` is output ``i`` (PX4's
``PWM_MAIN_FUNCi+1`` = Motor ``i+1``), so a vehicle uses the first of the core's
:data:`~fpga_hdl.chips.pwm_capture.core.CHANNELS` channels, one per rotor.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Collection, Sequence
from typing import NamedTuple

import numpy as np

from fpga_hdl.chips.pwm_capture.core import CHANNELS
from fpga_hdl.chips.pwm_capture.model import PwmCaptureModel
from fpga_hdl.top import PWM_RESULT_LATENCY_TICKS
from quad_model.frames import PWM_MAX_US, PWM_MIN_US, pwm_to_throttle

#: PX4 PWM_MAIN_DISn default: the pulse an ESC sees while the vehicle is disarmed.
PWM_DISARMED_US = PWM_MIN_US
#: PX4's PWM_MAIN_MINn/MAXn defaults: the pulses for actuator command 0 and 1.
DEFAULT_MOTOR_PWM_RANGE_US = (PWM_MIN_US, PWM_MAX_US)
#: The capture core's tick: 1 µs, the unit PX4 uses for PWM (fpga_hdl.chips.pwm_capture).
PWM_TICK_HZ = 1e6
#: No rising edge for this long and a channel counts as lost: the capture core's default,
#: and a usual ESC signal-loss time; the ESC then stops the motor.
PWM_TIMEOUT_S = 0.1


class Pulse(NamedTuple):
    """One PWM pulse on ``channel``: rising edge at ``start_us``, ``width_us`` long (a named
    tuple: the rig makes one per motor and PWM period)."""

    channel: int
    start_us: int
    width_us: int


class PwmTimingError(RuntimeError):
    """The frame's pulses cannot be replayed, or its capture read, at their exact times."""


def replay_periods(
    pulses: Sequence[Pulse], now_us: int, next_start_us: int, period_us: int, tick_us: float
) -> tuple[list[tuple[int, list[int]]], int]:
    """The PWM periods an RTL generator replays for one frame: widths in capture ticks
    (0: no pulse) for every period starting from ``next_start_us`` up to ``now_us``, and
    the next period start after them. Both RTL layers replay the autopilot's PWM so."""
    periods: dict[int, list[int]] = {}
    while next_start_us <= now_us:
        periods[next_start_us] = [0] * CHANNELS
        next_start_us += period_us
    for pulse in pulses:
        if pulse.start_us not in periods:
            raise PwmTimingError(
                f"PWM pulse on channel {pulse.channel} at {pulse.start_us} µs is not at a "
                f"period start of this frame (period {period_us} µs from 0)"
            )
        ticks = math.ceil(pulse.width_us / tick_us - 1e-9)
        if not 0 < ticks * tick_us < period_us:
            raise PwmTimingError(
                f"PWM pulse width {pulse.width_us} µs on channel {pulse.channel} is not "
                f"within one period ({period_us} µs)"
            )
        periods[pulse.start_us][pulse.channel] = ticks
    return sorted(periods.items()), next_start_us


class PwmOutput:
    """The autopilot's PWM outputs: pulses at ``pwm_hz``, widths latched at each period."""

    def __init__(
        self,
        channels: int,
        pwm_hz: int,
        range_us: tuple[float, float] = DEFAULT_MOTOR_PWM_RANGE_US,
    ) -> None:
        if not 50 <= pwm_hz <= 490:
            raise ValueError(f"pwm_hz must be within 50..490 Hz (standard ESC PWM), got {pwm_hz}")
        if not PWM_MIN_US <= range_us[0] < range_us[1] <= PWM_MAX_US:
            raise ValueError(
                f"range_us must satisfy {PWM_MIN_US:g} <= min < max <= {PWM_MAX_US:g} µs "
                f"(what the ESC input spans), got {range_us}"
            )
        self.range_us = range_us
        self.channels = channels
        self.period_us = round(1e6 / pwm_hz)
        self._disarmed_us = [round(PWM_DISARMED_US)] * channels
        self._widths_us = self._disarmed_us
        self._latest: tuple[tuple[float, ...], bool] | None = None  # not yet converted
        self._next_start_us = 0

    def command(self, motors: Sequence[float], armed: bool) -> None:
        """The latest actuator controls (0..1); latched at the next period start.

        Converted to widths only when a period starts: the autopilot answers every frame,
        the outputs latch at the PWM rate.
        """
        self._latest = (tuple(motors), armed)

    def pulses(self, until_us: int, dropped: Collection[int] = ()) -> list[Pulse]:
        """Pulses starting before ``until_us`` since the last call (whole µs widths)."""
        pulses = []
        while self._next_start_us < until_us:
            widths_us = self._latched_widths_us()
            for channel in range(self.channels):
                if channel not in dropped:
                    pulses.append(Pulse(channel, self._next_start_us, widths_us[channel]))
            self._next_start_us += self.period_us
        return pulses

    def _latched_widths_us(self) -> list[int]:
        if self._latest is not None:
            motors, armed = self._latest
            self._latest = None
            if armed:
                # Plain floats, not np.clip: for four motors numpy's call overhead was the
                # largest part of the TLM frame's PWM path (same IEEE operations).
                low_us, high_us = self.range_us
                span_us = high_us - low_us
                self._widths_us = [round(low_us + min(max(motor, 0.0), 1.0) * span_us)
                                   for motor in motors]  # fmt: skip
            else:
                self._widths_us = self._disarmed_us
        return self._widths_us


def throttle_from_capture(widths_us: Sequence[float], timed_out: Sequence[bool]) -> np.ndarray:
    """ESC throttle 0..1 from captured widths; a timed-out channel gives zero."""
    throttle = pwm_to_throttle(widths_us)
    throttle[np.asarray(timed_out, dtype=bool)] = 0.0
    return throttle


class PwmCapture:
    """The PWM capture results the rig reads at a frame time (fpga_hdl's tick-exact model).

    What SensorTop's host port shows, so with its fixed latency: a pulse edge first
    sampled at tick ``k`` is in a read at tick ``k + PWM_RESULT_LATENCY_TICKS`` (the
    core's input re-timing, then the publication into the system clock domain).
    :class:`fpga_hdl.chips.pwm_capture.model.PwmCaptureModel` recomputes a channel from its
    pulse history. Its results depend only on the last two rising edges, the last
    complete pulse and the time since the last rise, so the last three pulses of a
    channel (the newest may still be high) give the same answer as the whole history;
    a test checks that against random pulse trains with dropouts.
    """

    def __init__(self, channels: int, tick_hz: float = PWM_TICK_HZ,
                 timeout_s: float = PWM_TIMEOUT_S) -> None:  # fmt: skip
        self.model = PwmCaptureModel(
            tick_hz=tick_hz, timeout_s=timeout_s, latency_ticks=PWM_RESULT_LATENCY_TICKS
        )
        self._tick_us = 1e6 / tick_hz
        #: The tick in whole picoseconds, as the RTL layers count it: edges from integer µs.
        self._tick_ps = round(1e12 / tick_hz)
        self._timeout_us = timeout_s * 1e6
        self._latency_us = PWM_RESULT_LATENCY_TICKS * self._tick_us
        #: Per channel, the last three pulses as the clock edges that sample them.
        self._recent: list[deque[tuple[int, int]]] = [deque(maxlen=3) for _ in range(channels)]
        #: Per channel, the last pulse's rise and fall (µs).
        self._last_us: list[tuple[int, int]] = [(0, 0)] * channels
        self._widths_us = [0.0] * channels
        self._timed_out = [True] * channels
        #: Per channel, the earliest time its results can change: a fall or a timeout.
        self._next_change_us = [math.inf] * channels

    def capture(
        self, pulses: Sequence[Pulse], now_us: int
    ) -> tuple[tuple[float, ...], tuple[bool, ...]]:
        """Add the new pulses; return each channel's width (µs) and timeout flag at ``now_us``.

        A channel is recomputed only once a read may show a pulse end (its fall plus the
        result latency) or its timeout may have run out since the last result:
        between those events the width and timeout registers hold (a rise changes only
        the period, which the rig does not use).

        The clock edges that sample a pulse come from its whole µs in integer picoseconds,
        as the RTL layers replay it: through seconds as floats (the model's ``sampled``),
        an edge after 32 s of flight could land a tick late.
        """
        model, latency_us, tick_ps = self.model, self._latency_us, self._tick_ps
        recents, last_us, next_change_us = self._recent, self._last_us, self._next_change_us
        for channel, start_us, width_us in pulses:
            fall_us = start_us + width_us
            # The first edge at or after each time: a ceiling division.
            rise_edge = -(-start_us * 1_000_000 // tick_ps)
            fall_edge = -(-fall_us * 1_000_000 // tick_ps)
            recents[channel].append((rise_edge, fall_edge))
            last_us[channel] = (start_us, fall_us)
            seen_fall_us = fall_us + latency_us  # seen by a read
            if seen_fall_us < next_change_us[channel]:
                next_change_us[channel] = seen_fall_us
        now = None
        widths_us, timed_out = self._widths_us, self._timed_out
        for channel, recent in enumerate(recents):
            if now_us < next_change_us[channel]:
                continue
            if now is None:
                now = now_us * 1_000_000 // tick_ps  # the last edge at or before now
            width_ticks, _, timeout = model.capture_sampled(recent, now)
            widths_us[channel] = width_ticks * self._tick_us
            timed_out[channel] = timeout
            last_rise_us, last_fall_us = last_us[channel]
            seen_fall_us = last_fall_us + latency_us  # seen by a read
            pending_fall = seen_fall_us if seen_fall_us > now_us else math.inf
            timeout_at = math.inf if timeout else last_rise_us + self._timeout_us
            next_change_us[channel] = min(pending_fall, timeout_at)
        return tuple(widths_us), tuple(timed_out)
