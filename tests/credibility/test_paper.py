"""`credibility paper` against the paper's section 4, arithmetic written out by hand.

With K_e = 0.75, η = 0.75ε / sqrt((0.75ε)² + e²) (eq. (NormIndex)).
"""

import math

import pytest

from credibility.cli import main
from credibility.paper import paper_comparison


def _eta(e: float, eps: float) -> float:
    return 0.75 * eps / math.sqrt((0.75 * eps) ** 2 + e**2)


FIGURES = {fig.label: fig for fig in paper_comparison()}


@pytest.mark.parametrize(
    ("label", "recomputed_pct", "status"),
    [
        # Table 1: 0.75·6e-4 = 4.5e-4; 4.5/sqrt(4.5² + 2²) = 4.5/4.9244 = 0.91381
        ("Fig. 16(a), t < 21.5 s", 100 * 4.5 / math.sqrt(4.5**2 + 2**2), "within rounding"),
        ("Fig. 16(a), t > 21.5 s", 100 * 3.0 / math.sqrt(3.0**2 + 0.7**2), "match"),
        ("Fig. 16(b), t < 21.5 s", 100 * 3.0 / math.sqrt(3.0**2 + 1.4**2), "match"),
        ("Fig. 16(b), t > 21.5 s", 100 * 5.25 / math.sqrt(5.25**2 + 1.4**2), "match"),
        # Table 2: 0.75·0.0175 = 0.013125
        ("Real flight", 100.0, "match"),
        ("High-precision", 100 * 0.013125 / math.hypot(0.013125, 0.0046), "match"),
        ("Low-precision", 100 * 0.013125 / math.hypot(0.013125, 0.012), "match"),
        ("Error bounds", 60.0, "match"),
        # 0.013125 / sqrt(0.013125² + 0.231²) = 0.05673, not the printed 1.75 %
        ("Zero-output", 100 * 0.013125 / math.hypot(0.013125, 0.231), "mismatch"),
        # Frequency domain: 0.75·2.05 = 1.5375 dB, 0.75·13.6 = 10.2°
        ("η_mag (e_mag, ε_mag in dB)", 100 * 1.5375 / math.hypot(1.5375, 0.364), "match"),
        ("η_pha (e_pha, ε_pha in deg)", 100 * 10.2 / math.hypot(10.2, 2.27), "match"),
        # eq. (freqIndex) on the printed 97.3 % and 97.6 %: 97.450 %, not 97.63 %
        ("η_f", 100 * math.sqrt((0.973**2 + 0.976**2) / 2), "mismatch"),
        # eq. (aveP) on Table 1's printed η: sqrt((.913² + .974² + .906² + .966²)/4) = 94.02 %
        ("η̄_p", 100 * math.sqrt((0.913**2 + 0.974**2 + 0.906**2 + 0.966**2) / 4), "match"),
        ("η̄_t", 94.4, "match"),
        ("η̄_f", 97.63, "match"),
        # eq. (overall): sqrt(0.3·0.94² + 0.3·0.944² + 0.4·0.9763²) = 95.59 %, not 95.36 %
        ("η_all", 100 * math.sqrt(0.3 * 0.94**2 + 0.3 * 0.944**2 + 0.4 * 0.9763**2), "mismatch"),
        ("η_min", 90.6, "match"),
    ],
)
def test_recomputed_figures(label, recomputed_pct, status):
    fig = FIGURES[label]
    assert fig.recomputed_pct == pytest.approx(recomputed_pct, abs=1e-9)
    assert fig.status == status
    assert (fig.note != "") == (status != "match")


def test_every_printed_figure_is_covered():
    assert len(FIGURES) == 17


def test_table_1_rounding_range_contains_the_printed_value():
    fig = FIGURES["Fig. 16(a), t < 21.5 s"]
    # e ∈ [1.5e-4, 2.5e-4], ε ∈ [5.5e-4, 6.5e-4]
    assert fig.low_pct == pytest.approx(100 * _eta(2.5e-4, 5.5e-4))
    assert fig.high_pct == pytest.approx(100 * _eta(1.5e-4, 6.5e-4))
    assert fig.low_pct < fig.printed_pct < fig.high_pct


def test_paper_command_prints_the_side_by_side(capsys):
    assert main(["paper"]) == 0
    out = capsys.readouterr().out
    assert "Zero-output" in out
    assert "5.67" in out
    assert "mismatch" in out
    assert "1.75 % is the printed threshold" in out
