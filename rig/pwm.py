"""Actuator controls → PWM pulses on the autopilot's outputs → what the ESCs receive.

The autopilot side (:class:`PwmOutput`) behaves as PX4's ``pwm_out`` with its default
output functions: every ``1/pwm_hz`` a pulse starts whose width was latched from the
latest actuator controls, 1000 µs (``PWM_MAIN_DIS``/``PWM_MAIN_MIN``) to 2000 µs
(``PWM_MAIN_MAX``), 1000 µs while disarmed. So a new command reaches the motors only at the
next PWM period (up to 2.5 ms later at 400 Hz), as on the real rig. A dropped-out channel
emits no pulse at all. The pulses go to the PWM capture core (RTL) or its model (TLM), and
the captured widths, not the commands, drive the motors; a channel whose capture timed out
means zero thrust (the ESC's failsafe).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass

import numpy as np

from quad_model.frames import PWM_MIN_US, pwm_to_throttle, throttle_to_pwm

#: PX4 PWM_MAIN_DISn default: the pulse an ESC sees while the vehicle is disarmed.
PWM_DISARMED_US = PWM_MIN_US
#: Quad-X: the first four outputs drive the motors (PX4 MOTOR_ORDER).
MOTOR_CHANNELS = 4
#: No rising edge for this long and a channel counts as lost (4 periods at 400 Hz); the
#: ESC then stops the motor, as common ESC firmware does on a lost signal.
PWM_TIMEOUT_US = 10_000


@dataclass(frozen=True)
class Pulse:
    """One PWM pulse on ``channel``: rising edge at ``start_us``, ``width_us`` long."""

    channel: int
    start_us: int
    width_us: int


class PwmOutput:
    """The autopilot's PWM outputs: pulses at ``pwm_hz``, widths latched at each period."""

    def __init__(self, channels: int, pwm_hz: int) -> None:
        if not 50 <= pwm_hz <= 490:
            raise ValueError(f"pwm_hz must be within 50..490 Hz (standard ESC PWM), got {pwm_hz}")
        self.channels = channels
        self.period_us = round(1e6 / pwm_hz)
        self._widths_us = np.full(channels, PWM_DISARMED_US)
        self._next_start_us = 0

    def command(self, motors: Sequence[float], armed: bool) -> None:
        """The latest actuator controls (0..1); latched at the next period start."""
        self._widths_us = (
            throttle_to_pwm(motors) if armed else np.full(self.channels, PWM_DISARMED_US)
        )

    def pulses(self, until_us: int, dropped: Collection[int] = ()) -> list[Pulse]:
        """Pulses starting before ``until_us`` since the last call (whole µs widths)."""
        pulses = []
        while self._next_start_us < until_us:
            for channel in range(self.channels):
                if channel not in dropped:
                    width = round(float(self._widths_us[channel]))
                    pulses.append(Pulse(channel, self._next_start_us, width))
            self._next_start_us += self.period_us
        return pulses


def throttle_from_capture(widths_us: Sequence[float], timed_out: Sequence[bool]) -> np.ndarray:
    """ESC throttle 0..1 from captured widths; a timed-out channel gives zero."""
    throttle = pwm_to_throttle(widths_us)
    throttle[np.asarray(timed_out, dtype=bool)] = 0.0
    return throttle


class PwmCaptureTimeline:
    """Transaction-level PWM capture: per channel the last complete pulse and a timeout.

    A pulse counts once its falling edge (``start + width``) is in the past, as the
    capture core latches the width at the falling edge; a channel with no rising edge for
    :data:`PWM_TIMEOUT_US` is timed out and reads zero thrust.
    """

    def __init__(self, channels: int, timeout_us: int = PWM_TIMEOUT_US) -> None:
        self.timeout_us = timeout_us
        self._widths_us = [0.0] * channels
        self._last_rise_us = [None] * channels
        self._in_flight: list[Pulse] = []

    def capture(
        self, pulses: Sequence[Pulse], now_us: int
    ) -> tuple[tuple[float, ...], tuple[bool, ...]]:
        self._in_flight.extend(pulses)
        still_high = []
        for pulse in self._in_flight:
            if pulse.start_us + pulse.width_us <= now_us:
                self._widths_us[pulse.channel] = float(pulse.width_us)
                self._last_rise_us[pulse.channel] = pulse.start_us
            else:
                still_high.append(pulse)
        self._in_flight = still_high
        timed_out = tuple(
            rise is None or now_us - rise > self.timeout_us for rise in self._last_rise_us
        )
        return tuple(self._widths_us), timed_out
