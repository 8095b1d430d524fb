"""Frequency responses from sweep (or other broadband) data, the way CIFER builds them.

For each of several window lengths, scipy.signal's Welch cross/auto spectra give the H1
estimate G_xy/G_xx and the magnitude-squared coherence γ² = |G_xy|²/(G_xx G_yy), the
paper's η_co of eq. (bbb). Short windows average many segments (low random error, good
at high frequency); long windows resolve low frequencies. At each point of a log-spaced
grid over [f_a, f_b] the windows are combined with weights 1/ε_r², the inverse variance of
their random error (Bendat & Piersol: ε_r ≈ sqrt(1 − γ²) / (|γ| sqrt(2 n_d)), n_d the number
of averaged segments), which is what CIFER's composite windowing aims at. A window only
contributes where it holds at least ``MIN_CYCLES`` periods.
"""

from dataclasses import dataclass

import control
import numpy as np
import scipy.fft
from scipy import signal as sps

from credibility.errors import CredibilityError

#: Periods a window must hold before its estimate at a frequency is used (Hann leakage
#: makes the first bins above DC unreliable).
MIN_CYCLES = 2.0
#: Coherence is clipped away from 0 and 1 so that ε_r stays finite and positive.
_GAMMA2_CLIP = 1e-9
#: CIFER's default composite uses five windows.
DEFAULT_WINDOW_COUNT = 5


@dataclass(frozen=True, eq=False)
class FrequencyResponseEstimate:
    """An input→output frequency response on a grid, with its coherence and random error.

    ``response`` is a python-control ``FrequencyResponseData`` (omega in rad/s), so it can be
    compared directly with a model's transfer function using that library.
    """

    freqs_hz: np.ndarray
    response: control.FrequencyResponseData
    coherence: np.ndarray
    random_error: np.ndarray
    windows_s: tuple[float, ...]
    averages: tuple[int, ...]

    @property
    def complex_response(self) -> np.ndarray:
        return self.response.frdata[0, 0, :]

    @property
    def magnitude_db(self) -> np.ndarray:
        return 20.0 * np.log10(np.abs(self.complex_response))


def log_grid(band_hz: tuple[float, float], n_points: int) -> np.ndarray:
    """The paper's f_1 … f_{n_f}: n_points log-spaced over [f_a, f_b]."""
    f_a, f_b = band_hz
    if not 0.0 < f_a < f_b:
        raise CredibilityError(f"frequency band [{f_a:g}, {f_b:g}] Hz must have 0 < f_a < f_b")
    if n_points < 2:
        raise CredibilityError(f"n_points must be ≥ 2, got {n_points}")
    return np.geomspace(f_a, f_b, n_points)


def default_windows(record_s: float, band_hz: tuple[float, float]) -> tuple[float, ...]:
    """Five log-spaced windows from 20/ω_b (Tischler's shortest) to half the record."""
    longest = record_s / 5.0
    shortest = min(20.0 / (2.0 * np.pi * band_hz[1]), longest)
    return tuple(float(w) for w in np.geomspace(shortest, longest, DEFAULT_WINDOW_COUNT))


def welch_spectra(
    x: np.ndarray, y: np.ndarray, sample_rate_hz: float, nperseg: int, noverlap: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """One-sided Welch densities G_xx, G_yy, G_xy (Hann window, mean removed per segment),
    the same numbers as scipy.signal.welch / csd, and the number of segments n_d.

    Written by hand because scipy 1.17's csd detrends and transforms segment by segment in
    Python: a 30-minute 1 kHz log with a short window is a million calls. Here all
    segments of both signals go through one vectorized rfft.
    """
    step = nperseg - noverlap
    window = sps.get_window("hann", nperseg)
    window_spectrum = np.fft.rfft(window)
    spectra = []
    for series in (x, y):
        segments = np.lib.stride_tricks.sliding_window_view(series, nperseg)[::step]
        # Mean removal after the transform: FFT(w·(s − m)) = FFT(w·s) − m·FFT(w), one copy less.
        spectrum = scipy.fft.rfft(segments * window, axis=1, workers=-1)
        spectrum -= segments.mean(axis=1, keepdims=True) * window_spectrum
        spectra.append(spectrum)
    fx, fy = spectra
    scale = np.full(nperseg // 2 + 1, 2.0 / (sample_rate_hz * np.sum(window**2)))
    scale[0] /= 2.0
    if nperseg % 2 == 0:
        scale[-1] /= 2.0
    gxx = scale * np.mean(np.abs(fx) ** 2, axis=0)
    gyy = scale * np.mean(np.abs(fy) ** 2, axis=0)
    gxy = scale * np.mean(np.conj(fx) * fy, axis=0)
    freqs = np.fft.rfftfreq(nperseg, 1.0 / sample_rate_hz)
    return freqs, gxx, gyy, gxy, fx.shape[0]


def estimate_response(
    x: np.ndarray,
    y: np.ndarray,
    sample_rate_hz: float,
    freqs_hz: np.ndarray,
    windows_s: tuple[float, ...],
    overlap: float = 0.5,
) -> FrequencyResponseEstimate:
    """H1 response and coherence of uniformly sampled input ``x`` and output ``y``.

    Each window's spectra are interpolated linearly onto ``freqs_hz`` before H and γ² are
    formed, so magnitude and phase come from the same averaged spectra.
    """
    if not 0.0 <= overlap < 1.0:
        raise CredibilityError(f"window overlap must lie in [0, 1), got {overlap!r}")
    nyquist_hz = sample_rate_hz / 2.0
    if freqs_hz[-1] >= nyquist_hz:
        raise CredibilityError(
            f"f_b = {freqs_hz[-1]:g} Hz is not below the Nyquist frequency {nyquist_hz:g} Hz"
        )
    record_s = x.size / sample_rate_hz
    weight_sum = np.zeros_like(freqs_hz)
    h_sum = np.zeros(freqs_hz.size, dtype=complex)
    gamma2_sum = np.zeros_like(freqs_hz)
    averages = []
    for window_s in windows_s:
        nperseg = round(window_s * sample_rate_hz)
        if nperseg < 8 or window_s > record_s:
            raise CredibilityError(
                f"window {window_s:g} s must hold ≥ 8 samples and fit the {record_s:g} s record"
            )
        noverlap = round(overlap * nperseg)
        f, gxx, gyy, gxy, n_d = welch_spectra(x, y, sample_rate_hz, nperseg, noverlap)
        if n_d < 2:
            # One segment gives γ² = 1 at every frequency whatever the data (and ε_r = 0),
            # so that window would pass the coherence gate and outweigh every other one.
            raise CredibilityError(
                f"window {window_s:g} s fits only once in the {record_s:g} s record; a "
                "coherence needs at least 2 averaged segments (use a shorter window)"
            )
        averages.append(n_d)
        sxy = np.interp(freqs_hz, f, gxy.real) + 1j * np.interp(freqs_hz, f, gxy.imag)
        sxx = np.interp(freqs_hz, f, gxx)
        syy = np.interp(freqs_hz, f, gyy)
        if np.any(sxx <= 0.0) or np.any(syy <= 0.0):
            raise CredibilityError(
                "the input or output has no power in the band: a constant signal cannot be "
                "analysed (is the excitation in this segment?)"
            )
        gamma2 = np.clip(np.abs(sxy) ** 2 / (sxx * syy), _GAMMA2_CLIP, 1.0 - _GAMMA2_CLIP)
        eps_r = np.sqrt(1.0 - gamma2) / (np.sqrt(gamma2) * np.sqrt(2.0 * n_d))
        weight = np.where(freqs_hz * window_s >= MIN_CYCLES, 1.0 / eps_r**2, 0.0)
        weight_sum += weight
        h_sum += weight * (sxy / sxx)
        gamma2_sum += weight * gamma2
    if np.any(weight_sum == 0.0):
        f_low = freqs_hz[weight_sum == 0.0][0]
        raise CredibilityError(
            f"no window resolves {f_low:.3g} Hz: the longest window "
            f"{max(windows_s):g} s holds fewer than {MIN_CYCLES:g} periods; raise f_a or use a "
            "longer record"
        )
    response = control.frd(h_sum / weight_sum, 2.0 * np.pi * freqs_hz)
    return FrequencyResponseEstimate(
        freqs_hz=freqs_hz,
        response=response,
        coherence=gamma2_sum / weight_sum,
        random_error=1.0 / np.sqrt(weight_sum),
        windows_s=tuple(windows_s),
        averages=tuple(averages),
    )


def phase_pair_deg(reference: np.ndarray, other: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unwrapped phases (deg) of two responses, unwrapped consistently for differencing.

    The reference phase is unwrapped along the grid; the other curve is the reference plus
    their unwrapped phase difference ∠(other/reference), shifted by a multiple of 360° so
    that the median difference lies in (−180°, 180°]. Unwrapping each curve on its own
    could leave them a full turn apart and count 360° as error.
    """
    ref_deg = np.degrees(np.unwrap(np.angle(reference)))
    diff_deg = np.degrees(np.unwrap(np.angle(other / reference)))
    diff_deg -= 360.0 * np.round(np.median(diff_deg) / 360.0)
    return ref_deg, ref_deg + diff_deg
