"""Real-time pacing: simulated time runs at most ``speed`` times the wall clock, kept by
sleeping between frames only, so lockstep and determinism are untouched (PX4's
``PX4_SIM_SPEED_FACTOR`` plays the same part for its simulators)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

#: Sleeps shorter than this are skipped (the next frame catches up): at 1 kHz a sleep per
#: frame would cost more in system calls than it paces.
MIN_SLEEP_S = 0.002


def parse_speed(text: str) -> float:
    """``"max"`` (as fast as possible) or a positive factor of real time (``"1"``, ``"0.5"``)."""
    if text.strip().lower() == "max":
        return math.inf
    try:
        speed = float(text)
    except ValueError:
        speed = math.nan
    if not speed > 0 or math.isinf(speed):
        raise ValueError(f"--speed {text!r}: expected 'max' or a positive factor of real time")
    return speed


class Pacer:
    """Holds simulated time back to ``speed`` × the wall time since it was made."""

    def __init__(self, speed: float, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:  # fmt: skip
        self.speed = speed
        self._clock, self._sleep = clock, sleep
        self._wall_start = clock()

    def wait(self, simulated_s: float) -> None:
        """Sleep until ``simulated_s`` of simulated time is due on the wall clock."""
        if math.isinf(self.speed):
            return
        ahead_s = self._wall_start + simulated_s / self.speed - self._clock()
        if ahead_s >= MIN_SLEEP_S:
            self._sleep(ahead_s)
