"""What a report could not compare as asked, or compared with a known bias.

Every test of a plan either gets a score or is listed as not scored with its reason, and
each such reason or bias is a :class:`Caveat` on the report (a section near the top of the
HTML, the ``warnings`` of the JSON), so nothing the plan asks for is dropped silently. The
thresholds below decide when a difference between logs is worth a warning; each says why.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from credibility.errors import NotScorable, Reason
from credibility.signals import Signal

#: A reason a test is not scored (``errors.Reason``), a bias of a scored test, or a line
#: the log reader reported.
Kind = Reason | Literal["sample_rate_mismatch", "few_samples", "epsilon_below_noise", "log_reader"]

#: Rates more than an octave apart. A σ of samples averaged over their logging interval
#: (PX4's vehicle_imu, the rig's sensor_combined) scales with the square root of the rate,
#: so an octave alone can move it by √2 (41 %), eight times K_p = 5 %; a step's peak and
#: crossings are resolved twice as coarsely. A curve interpolated onto a grid more than an
#: octave finer than its samples has more than half of the grid's band above its own
#: Nyquist frequency, where it holds no information and linear interpolation leaves images
#: and a sinc² roll-off (−7.8 dB at its Nyquist). Within an octave lie the ordinary
#: differences between a rig's and a flight controller's logging rates (200 against
#: 250 Hz), which would only bury the warnings that matter.
RATE_RATIO_MAX = 2.0

_STEP_CONSEQUENCE = (
    "the step is resolved to {low_period:.3g} s in one log and {high_period:.3g} s in the "
    "other: a peak or a crossing between samples is missed"
)
#: What a sample-rate mismatch does to each statistic; ``mean`` and ``steady_state`` are
#: means, unbiased at any rate, and ``value`` reads no log.
RATE_CONSEQUENCES = {
    "std": "if the samples were averaged over each logging interval, σ differs by bandwidth "
    "(up to {sqrt_ratio:.2g}×) as well as by model; point samples compare, but fewer",
    "overshoot": _STEP_CONSEQUENCE,
    "rise_time": _STEP_CONSEQUENCE,
    "settling_time": _STEP_CONSEQUENCE,
    "time": "the curve is interpolated between its samples: detail above {low_nyquist:.3g} Hz "
    "is missing from it and counts as error",
    "frequency": "the signal is interpolated between its samples: above {low_nyquist:.3g} Hz "
    "the spectra hold images and a sinc² roll-off, not the response",
}

#: An exact model's statistic still differs from the real one by sampling noise: the
#: standard error of a σ of n Gaussian samples is σ / sqrt(2 (n − 1)), of a mean
#: s / sqrt(n), combined over the real and the sim logs. When that exceeds ε_p, sampling
#: noise alone can put e_p above ε_p: with K_p = 5 % a real σ from fewer than about 200
#: samples against a long sim log does, with 10 % fewer than about 50. Correlated samples
#: (a high-passed σ, coloured noise) make it worse, not better. More samples fix it, so the
#: test is still scored, with this warning.
FEW_SAMPLE_PARAMETERS = ("mean", "std")


@dataclass(frozen=True)
class Caveat:
    """One warning: the test it concerns (None for the whole report), its kind, and one
    line naming the log, the signal, the numbers and what follows from them."""

    test: str | None
    kind: Kind
    message: str


@dataclass(frozen=True)
class Logged:
    """How one signal was logged over one segment, for a message that names the numbers."""

    label: str
    rate_hz: float
    samples: int
    duration_s: float

    @classmethod
    def of(cls, role: str, sig: Signal) -> "Logged":
        """``sig`` as logged in the log of ``role`` (roles tell apart two autopilot.ulg)."""
        first, last = sig.span_s()
        label = f"{sig.name} in {role} ({Path(sig.source).name})"
        return cls(label, sig.rate_hz(), sig.time_s.size, last - first)

    def __str__(self) -> str:
        return (
            f"{self.label} at {self.rate_hz:.3g} Hz ({self.samples} samples over "
            f"{self.duration_s:.3g} s)"
        )


def rate_mismatch(test: str, first: Logged, second: Logged, consequence: str) -> Caveat | None:
    """A ``sample_rate_mismatch`` warning when two logs of one statistic are more than
    RATE_RATIO_MAX apart in rate. ``consequence`` may use {low_nyquist}, {high_nyquist}
    (Hz), {low_period}, {high_period} (s) and {sqrt_ratio}."""
    low, high = sorted((first.rate_hz, second.rate_hz))
    if high <= RATE_RATIO_MAX * low:
        return None
    then = consequence.format(
        low_nyquist=low / 2,
        high_nyquist=high / 2,
        low_period=1 / low,
        high_period=1 / high,
        sqrt_ratio=np.sqrt(high / low),
    )
    return Caveat(
        test, "sample_rate_mismatch", f"{first} against {second}: {high / low:.1f}× apart; {then}"
    )


def interpolated(test: str, logged: Logged, grid: Logged, consequence: str) -> Caveat | None:
    """A ``sample_rate_mismatch`` warning when a signal is interpolated onto a grid more than
    RATE_RATIO_MAX times faster than its samples; a faster signal is point-sampled by the
    grid, as a logger would sample it, which biases neither log against the other."""
    if logged.rate_hz >= grid.rate_hz:
        return None
    return rate_mismatch(test, logged, grid, consequence)


def exact_model_error(parameter: str, real: np.ndarray, sim_samples: int) -> float:
    """The standard error of p_e − p_s for a sim that matches the real log exactly but for
    its own sampling: the real statistic's spread over ``real.size`` and ``sim_samples``."""
    spread = float(real.std(ddof=1)) if real.size > 1 else float("inf")
    if parameter == "mean":
        return spread * np.sqrt(1.0 / real.size + 1.0 / sim_samples)
    return spread * np.sqrt(0.5 / max(real.size - 1, 1) + 0.5 / max(sim_samples - 1, 1))


def few_samples(
    test: str, parameter: str, real: Logged, values: np.ndarray, sim: Logged, threshold: float
) -> Caveat | None:
    """A ``few_samples`` warning when sampling noise alone can exceed ε_p (see above)."""
    error = exact_model_error(parameter, values, sim.samples)
    if error <= threshold:
        return None
    name = "σ" if parameter == "std" else "mean"
    return Caveat(
        test,
        "few_samples",
        f"{name} of {real} against {sim.samples} samples in {sim.label}: an exact model's "
        f"{name} would still differ by {error:.3g} (standard error), more than ε_p = "
        f"{threshold:.3g}, so sampling noise alone can put η_p below the pass mark (a longer "
        "segment or a higher logging rate fixes it)",
    )


def require_epsilon(symbol: str, epsilon: float, rule: str, unit: str = "") -> None:
    """Raise ``unscorable_epsilon`` when ε is not > 0: eq. (NormIndex) is then undefined
    (a constant real curve, p_e = p_s = 0)."""
    if not epsilon > 0.0:
        unit = f" {unit}" if unit else ""
        raise NotScorable(
            "unscorable_epsilon",
            f"{symbol} = {epsilon:.3g}{unit} ({rule}) is not > 0, so η is undefined; give the "
            "test a threshold",
        )


def epsilon_below_noise(
    test: str, symbol: str, epsilon: float, rule: str, floor: float, source: str, unit: str = ""
) -> Caveat | None:
    """An ``epsilon_below_noise`` warning when ε lies below the noise floor of the real
    log's curve: even a model that reproduces the flight exactly then has e ≥ ε and scores
    below the pass mark, so η measures the log's noise, not the model. The range-based ε of
    a near-flat curve is the usual cause. More samples do not lower the floor of a curve;
    the test is still scored, as the paper's method defines it, with this warning."""
    if epsilon >= floor:
        return None
    unit = f" {unit}" if unit else ""
    return Caveat(
        test,
        "epsilon_below_noise",
        f"{symbol} = {epsilon:.3g}{unit} ({rule}) is below the real log's noise floor "
        f"{floor:.3g}{unit} ({source}): even an exact model would score below the pass mark, "
        "so this η measures the log's noise, not the model",
    )
