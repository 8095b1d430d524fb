"""Frequency responses against a known transfer function (closed form)."""

import control
import numpy as np
import pytest
from scipy import signal as sps

from credibility import spectral
from credibility.errors import CredibilityError

RATE_HZ = 100.0


def _plant() -> control.TransferFunction:
    """A 3 Hz, ζ = 0.4 second-order plant sampled with Tustin at RATE_HZ."""
    s = control.tf("s")
    wn = 2 * np.pi * 3.0
    return control.sample_system(wn**2 / (s**2 + 2 * 0.4 * wn * s + wn**2), 1 / RATE_HZ, "tustin")


def _true_response(plant, freqs_hz):
    return plant(np.exp(2j * np.pi * freqs_hz / RATE_HZ))


def test_sweep_through_a_known_plant_gives_its_bode_and_unit_coherence():
    t = np.arange(0.0, 120.0, 1 / RATE_HZ)
    x = sps.chirp(t, 0.05, t[-1], 20.0, method="logarithmic")
    plant = _plant()
    y = control.forced_response(plant, T=t, U=x).outputs
    freqs = spectral.log_grid((0.2, 15.0), 30)
    est = spectral.estimate_response(
        x, y, RATE_HZ, freqs, spectral.default_windows(120.0, (0.2, 15.0))
    )
    truth = _true_response(plant, freqs)
    np.testing.assert_allclose(est.magnitude_db, 20 * np.log10(np.abs(truth)), atol=0.15)
    np.testing.assert_allclose(np.degrees(np.angle(est.complex_response / truth)), 0.0, atol=1.0)
    assert est.coherence.min() > 0.98
    # The response is a python-control FRD: it compares with the model in that library.
    assert isinstance(est.response, control.FrequencyResponseData)
    np.testing.assert_allclose(est.response.omega, 2 * np.pi * freqs)


@pytest.mark.parametrize("noise_std", [0.3, 1.0])
def test_output_noise_lowers_coherence_as_theory_says(noise_std):
    """White input σ_x = 1 and white output noise σ_n: γ² = |H|² / (|H|² + σ_n²)."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 300.0, 1 / RATE_HZ)
    x = rng.standard_normal(t.size)
    s = control.tf("s")
    plant = control.sample_system(1 / (s / (2 * np.pi * 5.0) + 1), 1 / RATE_HZ, "tustin")
    y = control.forced_response(plant, T=t, U=x).outputs + noise_std * rng.standard_normal(t.size)
    freqs = spectral.log_grid((1.0, 20.0), 15)
    est = spectral.estimate_response(x, y, RATE_HZ, freqs, (1.0, 2.0, 4.0))
    h2 = np.abs(_true_response(plant, freqs)) ** 2
    theory = h2 / (h2 + noise_std**2)
    # Random error of γ̂² is about sqrt(2)(1 − γ²)/(|γ| sqrt(n_d)) with n_d ≥ 149 here: < 0.05.
    np.testing.assert_allclose(est.coherence, theory, atol=0.05)


def test_random_error_follows_bendat_and_piersol():
    rng = np.random.default_rng(3)
    x = rng.standard_normal(20_000)
    y = x + rng.standard_normal(20_000)  # γ² = 1/2 at every frequency
    freqs = spectral.log_grid((2.0, 20.0), 5)
    est = spectral.estimate_response(x, y, RATE_HZ, freqs, (2.0,))
    n_d = est.averages[0]
    expected = np.sqrt(1 - 0.5) / (np.sqrt(0.5) * np.sqrt(2 * n_d))
    np.testing.assert_allclose(est.random_error, expected, rtol=0.25)


def test_phase_pair_unwraps_both_curves_together():
    f = np.linspace(1, 10, 50)
    ref = np.exp(-1j * 2 * np.pi * f * 0.2)  # a 0.2 s delay: phase runs to −720°
    other = ref * np.exp(-1j * np.radians(5.0))
    ref_deg, other_deg = spectral.phase_pair_deg(ref, other)
    np.testing.assert_allclose(ref_deg, -360 * f * 0.2, atol=1e-9)
    np.testing.assert_allclose(other_deg - ref_deg, -5.0, atol=1e-9)


def test_bad_band_or_signal_is_a_clear_error():
    x = np.random.default_rng(1).standard_normal(1000)
    with pytest.raises(CredibilityError, match=r"^no window resolves 0.1 Hz"):
        spectral.estimate_response(x, x, RATE_HZ, np.array([0.1, 1.0]), (2.0,))
    with pytest.raises(CredibilityError, match=r"not below the Nyquist frequency 50 Hz"):
        spectral.estimate_response(x, x, RATE_HZ, np.array([1.0, 60.0]), (2.0,))
    with pytest.raises(CredibilityError, match=r"no power in the band"):
        spectral.estimate_response(np.zeros(1000), x, RATE_HZ, np.array([1.0, 5.0]), (2.0,))


@pytest.mark.parametrize(("nperseg", "noverlap"), [(64, 32), (101, 50), (256, 0)])
def test_welch_spectra_equal_scipy(nperseg, noverlap):
    rng = np.random.default_rng(5)
    x, y = rng.standard_normal((2, 5000)) + 3.0
    f, gxx, gyy, gxy, n_d = spectral.welch_spectra(x, y, RATE_HZ, nperseg, noverlap)
    kwargs = {"fs": RATE_HZ, "nperseg": nperseg, "noverlap": noverlap}
    np.testing.assert_allclose(gxx, sps.welch(x, **kwargs)[1], rtol=1e-9)
    np.testing.assert_allclose(gyy, sps.welch(y, **kwargs)[1], rtol=1e-9)
    np.testing.assert_allclose(gxy, sps.csd(x, y, **kwargs)[1], rtol=1e-9)
    np.testing.assert_allclose(f, sps.welch(x, **kwargs)[0])
    assert n_d == 1 + (5000 - nperseg) // (nperseg - noverlap)


def test_a_window_that_fits_once_is_refused():
    """One segment makes γ² ≡ 1 whatever the data: pure noise in, unrelated noise out."""
    rng = np.random.default_rng(3)
    x, y = rng.standard_normal(1000), rng.standard_normal(1000)  # 10 s at RATE_HZ
    freqs = spectral.log_grid((0.5, 5.0), 10)
    with pytest.raises(CredibilityError, match=r"window 8 s fits only once in the 10 s record"):
        spectral.estimate_response(x, y, RATE_HZ, freqs, (2.0, 8.0))
    assert spectral.estimate_response(x, y, RATE_HZ, freqs, (2.0, 5.0)).coherence.max() < 0.6
