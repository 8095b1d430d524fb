"""Logged signals and what the method does to them in time: windows, grids, smoothing,
alignment and the performance parameters of a curve.

Real logs are irregularly sampled, with dropouts and NaNs; every function here either
handles that explicitly or raises a one-line ``CredibilityError`` that names the signal,
the file and the time span.
"""

from dataclasses import dataclass

import numpy as np
from scipy import signal as sps
from scipy import stats

from credibility.errors import CredibilityError, NotScorable


@dataclass(frozen=True, eq=False)
class Signal:
    """One scalar time series read from a log: sample times in seconds and values in the
    plan's units. ``source`` is the log file, so an error can name it."""

    name: str
    source: str
    time_s: np.ndarray
    values: np.ndarray

    @property
    def where(self) -> str:
        return f"{self.name} in {self.source}"

    def span_s(self) -> tuple[float, float]:
        return float(self.time_s[0]), float(self.time_s[-1])

    def median_interval_s(self) -> float:
        """The nominal sample interval: robust to the dropouts and jitter of real logs."""
        if self.time_s.size < 2:
            raise NotScorable("short_signal", f"{self.where}: fewer than 2 samples")
        return float(np.median(np.diff(self.time_s)))

    def rate_hz(self) -> float:
        """The nominal sample rate, so a report can say at what rate each log was logged."""
        return 1.0 / self.median_interval_s()


def window(
    sig: Signal, segment_s: tuple[float, float], max_gap_s: float, drop_nan: bool = False
) -> Signal:
    """The samples of ``sig`` inside ``segment_s``, checked before any number is computed.

    A segment outside the log's span is an error (never a silent truncation), NaNs are an
    error unless the plan treats them as dropouts, and a dropout longer than ``max_gap_s``
    is an error because interpolating across it would invent data.
    """
    t_a, t_b = segment_s
    if not t_a < t_b:
        raise CredibilityError(f"{sig.where}: segment [{t_a:g}, {t_b:g}] s is empty")
    first, last = sig.span_s()
    if t_a < first or t_b > last:
        raise NotScorable(
            "short_signal",
            f"{sig.where}: segment [{t_a:g}, {t_b:g}] s is outside the logged span "
            f"[{first:.3f}, {last:.3f}] s",
        )
    inside = (sig.time_s >= t_a) & (sig.time_s <= t_b)
    time_s, values = sig.time_s[inside], sig.values[inside]
    nan = ~np.isfinite(values)
    if nan.any():
        if not drop_nan:
            raise CredibilityError(
                f"{sig.where}: {int(nan.sum())} NaN/inf samples in [{t_a:g}, {t_b:g}] s, the "
                f"first at t = {time_s[nan][0]:.3f} s (set drop_nan = true to treat them as "
                "dropouts)"
            )
        time_s, values = time_s[~nan], values[~nan]
    edges = np.concatenate(([t_a], time_s, [t_b]))
    gaps = np.diff(edges)
    worst = int(np.argmax(gaps))
    if gaps[worst] > max_gap_s:
        raise CredibilityError(
            f"{sig.where}: {gaps[worst]:.3f} s without samples at t = {edges[worst]:.3f} s "
            f"in [{t_a:g}, {t_b:g}] s exceeds max_gap_s = {max_gap_s:g}"
        )
    return Signal(sig.name, sig.source, time_s, values)


def max_gap(sig: Signal) -> float:
    """The longest interval without a sample, reported so a reader sees the dropouts."""
    return float(np.diff(sig.time_s).max()) if sig.time_s.size > 1 else 0.0


def interval_means(sig: Signal, interval_s: float) -> Signal:
    """The samples averaged over consecutive ``interval_s`` intervals from the first sample,
    each mean stamped at its interval's last sample: what PX4's vehicle_imu does to the raw
    IMU at IMU_INTEG_RATE. A signal already logged at about that interval (median interval
    above two thirds of it) is returned as is: its samples are such means already."""
    if sig.median_interval_s() > interval_s * 2.0 / 3.0:
        return sig
    bins = np.floor((sig.time_s - sig.time_s[0]) / interval_s).astype(np.int64)
    starts = np.flatnonzero(np.diff(bins, prepend=-1))
    counts = np.diff(np.append(starts, bins.size))
    means = np.add.reduceat(sig.values, starts) / counts
    return Signal(sig.name, sig.source, sig.time_s[starts + counts - 1], means)


def resample(sig: Signal, grid_s: np.ndarray) -> np.ndarray:
    """Values on ``grid_s`` by linear interpolation (the paper's t_1 … t_{n_t} of eq. (RQ))."""
    return np.interp(grid_s, sig.time_s, sig.values)


#: Δ⁴ of white noise of σ = 1 has σ = sqrt(1 + 16 + 36 + 16 + 1) (binomial coefficients).
_DIFF4_NOISE_GAIN = float(np.sqrt(70.0))


def noise_sigma(values: np.ndarray) -> float:
    """The σ of the white noise on a uniformly sampled curve, robust to the curve itself.

    The 4th difference cancels any cubic, so a curve resolved by its samples barely
    contributes; its median absolute deviation (scipy's, scaled to σ) ignores the few
    large values a step or a spike leaves. Used to tell a threshold ε that lies below the
    noise from one a model can be scored against. 0 for fewer than 5 samples.
    """
    if values.size < 5:
        return 0.0
    diff4 = np.diff(values, n=4)
    return float(stats.median_abs_deviation(diff4, scale="normal")) / _DIFF4_NOISE_GAIN


def smooth(values: np.ndarray, interval_s: float, window_s: float, polyorder: int) -> np.ndarray:
    """Savitzky–Golay smoothing, the curve smoothing the paper asks for with eq. (RQ).

    The window is rounded to the nearest odd number of samples.
    """
    length = round(window_s / interval_s) | 1
    if length <= polyorder:
        raise CredibilityError(
            f"smoothing window {window_s:g} s is {length} samples at {interval_s:g} s, not more "
            f"than polyorder {polyorder}"
        )
    return sps.savgol_filter(values, length, polyorder)


def highpass(values: np.ndarray, interval_s: float, cutoff_hz: float) -> np.ndarray:
    """2nd-order Butterworth high-pass, zero phase: separates vibration from slow motion.

    Samples are filtered as logged, at their median interval: interpolating them onto a
    uniform grid first would lower the variance of white noise and bias σ low.
    """
    nyquist_hz = 0.5 / interval_s
    if not 0.0 < cutoff_hz < nyquist_hz:
        raise CredibilityError(
            f"high-pass cutoff {cutoff_hz:g} Hz must lie in (0, {nyquist_hz:g}) Hz (Nyquist)"
        )
    sos = sps.butter(2, cutoff_hz, btype="highpass", fs=1.0 / interval_s, output="sos")
    return sps.sosfiltfilt(sos, values)


def first_crossing(
    sig: Signal, threshold: float, direction: str, search_s: tuple[float, float]
) -> float:
    """Time of the first ``direction`` ("rising" or "falling") crossing of ``threshold``
    inside ``search_s``, linearly interpolated between samples: an event such as takeoff."""
    inside = (sig.time_s >= search_s[0]) & (sig.time_s <= search_s[1]) & np.isfinite(sig.values)
    t, y = sig.time_s[inside], sig.values[inside]
    above = y >= threshold
    if direction == "falling":
        above = ~above
    edges = np.flatnonzero(~above[:-1] & above[1:])
    if edges.size == 0:
        raise CredibilityError(
            f"{sig.where}: no {direction} crossing of {threshold:g} in "
            f"[{search_s[0]:g}, {search_s[1]:g}] s"
        )
    i = edges[0]
    return float(t[i] + (threshold - y[i]) * (t[i + 1] - t[i]) / (y[i + 1] - y[i]))


def correlation_lag(
    reference: Signal,
    other: Signal,
    segment_s: tuple[float, float],
    other_start_s: float,
    max_lag_s: float,
    interval_s: float,
) -> float:
    """The shift (s) to add to ``other_start_s`` so that ``other`` best matches ``reference``
    over ``segment_s``: the peak of the normalized cross-correlation within ±max_lag_s,
    refined to a fraction of a sample by a parabola through the peak.

    The search range is clipped to the span ``other`` covers.
    """
    duration = segment_s[1] - segment_s[0]
    ref_grid = np.arange(segment_s[0], segment_s[1], interval_s)
    first, last = other.span_s()
    lo = max(-max_lag_s, first - other_start_s)
    hi = min(max_lag_s, last - other_start_s - duration)
    if hi < lo:
        raise NotScorable(
            "short_signal",
            f"{other.where}: no room to align [{segment_s[0]:g}, {segment_s[1]:g}] s",
        )
    lags = np.arange(np.ceil(lo / interval_s), np.floor(hi / interval_s) + 1) * interval_s
    other_grid = other_start_s + lags[0] + np.arange(ref_grid.size + lags.size - 1) * interval_s
    ref = resample(reference, ref_grid)
    oth = resample(other, other_grid)
    ref = ref - ref.mean()
    cross = sps.correlate(oth, ref, mode="valid", method="fft")
    # Energy of each candidate window of `other`, from cumulative sums: Pearson per lag.
    csum = np.concatenate(([0.0], np.cumsum(oth)))
    csum2 = np.concatenate(([0.0], np.cumsum(oth**2)))
    n = ref.size
    win_sum = csum[n:] - csum[:-n]
    win_energy = csum2[n:] - csum2[:-n] - win_sum**2 / n
    norm = np.sqrt(np.maximum(win_energy, 1e-300) * np.sum(ref**2))
    score = cross / norm
    k = int(np.argmax(score))
    frac = 0.0
    if 0 < k < score.size - 1:
        a, b, c = score[k - 1], score[k], score[k + 1]
        curvature = a - 2.0 * b + c
        if curvature < 0.0:
            frac = 0.5 * (a - c) / curvature
    return float(lags[k] + frac * interval_s)


@dataclass(frozen=True)
class StepMetrics:
    """Classical step-response parameters, times measured from the segment start."""

    initial: float
    steady_state: float
    overshoot_pct: float
    rise_time_s: float
    settling_time_s: float


def step_metrics(
    time_s: np.ndarray, values: np.ndarray, settling_band: float, steady_window_s: float
) -> StepMetrics:
    """Overshoot, 10–90 % rise time, settling time and steady state of a step in a segment.

    The step starts at the first sample (the plan puts the segment start at the command);
    the steady state is the mean over the last ``steady_window_s``; settling is the last
    time the curve is outside ±``settling_band``·|step| around it.
    """
    t = time_s - time_s[0]
    initial = float(values[0])
    steady = float(values[t >= t[-1] - steady_window_s].mean())
    step = steady - initial
    spread = float(np.std(values[t >= t[-1] - steady_window_s]))
    if step == 0.0 or abs(step) < 3.0 * spread:
        raise CredibilityError(
            f"no step in the segment: initial {initial:g} → steady state {steady:g} is within "
            f"3σ = {3 * spread:g} of the steady-state noise"
        )
    progress = (values - initial) / step  # 0 at the start, 1 at steady state, either sign
    overshoot = max(0.0, float(progress.max()) - 1.0) * 100.0
    reached_10 = np.flatnonzero(progress >= 0.1)
    reached_90 = np.flatnonzero(progress >= 0.9)
    rise = float(t[reached_90[0]] - t[reached_10[0]])
    outside = np.flatnonzero(np.abs(progress - 1.0) > settling_band)
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] == t.size - 1:
        raise CredibilityError(
            f"the response does not settle within ±{settling_band:g}·|step| before the segment ends"
        )
    else:
        settling = float(t[outside[-1] + 1])
    return StepMetrics(initial, steady, overshoot, rise, settling)
