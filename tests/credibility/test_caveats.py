"""A report that says what it could not compare: warnings with their numbers, tests listed
as not scored with their reason, and an exit code for each verdict, through the real CLI."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from credibility.assess import assess
from credibility.cli import main
from credibility.errors import CredibilityError
from credibility.plan import load_plan

SLOW_HZ = 8.5  # an older PX4's logging rate (issue 14)
FAST_HZ = 200.0
SIGMA = 0.1


def _log(path, rate_hz: float, seed: int, **columns) -> None:
    """A CSV log over 0–12 s: white noise of σ = SIGMA on ``v.noise``, a 0.5 Hz sine on
    ``v.wave``, and any constant or function-of-time ``columns``."""
    t = np.arange(0.0, 12.0, 1.0 / rate_hz)
    rng = np.random.default_rng(seed)
    frame = {"time_s": t, "v.noise": rng.normal(0.0, SIGMA, t.size), "v.wave": np.sin(np.pi * t)}
    for name, value in columns.items():
        frame[f"v.{name}"] = value(t) if callable(value) else np.full(t.size, value)
    pd.DataFrame(frame).to_csv(path, index=False)


def _plan(directory, tests: str, logs: str = 'real = "real.csv"\nsim = "sim.csv"') -> str:
    path = directory / "plan.toml"
    path.write_text(f"[plan]\neps_min = 0.5\n\n[logs]\n{logs}\n{tests}")
    return str(path)


def _report(plan: str, *options: str) -> tuple[int, dict, str]:
    out = f"{plan[: -len('plan.toml')]}out"
    code = main(["report", plan, "--out", out, *options])
    with open(f"{out}/plan.json", encoding="utf-8") as stream:
        report = json.load(stream)
    with open(f"{out}/plan.html", encoding="utf-8") as stream:
        return code, report, stream.read()


def _warnings(report: dict, test: str) -> dict[str, str]:
    """kind → message of one test's warnings (each kind once per test here)."""
    entry = next(t for t in report["tests"] if t["name"] == test)
    return {w["kind"]: w["message"] for w in entry["warnings"]}


def _eta(e: float, eps: float) -> float:
    return 0.75 * eps / math.hypot(0.75 * eps, e)


RATES = """
[[tests]]
name = "noise_sigma"
kind = "performance"
parameter = "std"
signal = "v.noise"
segment_s = [2.05, 10.05]
real = "slow"
sim = "fast"

[[tests]]
name = "level_mean"
kind = "performance"
parameter = "mean"
signal = "v.level"
segment_s = [2.05, 10.05]
real = "slow"
sim = "fast"

[[tests]]
name = "wave_on_the_slow_grid"
kind = "time"
signal = "v.wave"
segment_s = [2.05, 10.05]
real = "slow"
sim = "fast"

[[tests]]
name = "slow_wave_on_the_fast_grid"
kind = "time"
signal = "v.wave"
segment_s = [2.05, 10.05]
real = "fast"
sim = "slow"
"""


def test_a_low_rate_log_warns_with_its_rates_and_sample_counts(tmp_path):
    """The issue's case: the real σ from 68 samples at 8.5 Hz against the sim's 200 Hz."""
    _log(tmp_path / "slow.csv", SLOW_HZ, seed=1, level=10.0)
    _log(tmp_path / "fast.csv", FAST_HZ, seed=2, level=10.0)
    plan = _plan(tmp_path, RATES, 'slow = "slow.csv"\nfast = "fast.csv"')
    code, report, html = _report(plan)
    assert code in (0, 1)  # every test is scored: a verdict, with warnings
    assert report["summary"]["not_scored"] == []
    # [2.05, 10.05] s at 8.5 Hz holds the samples 18 … 85: 68 of them over 67 / 8.5 s.
    sigma = _warnings(report, "noise_sigma")
    slow = "v.noise in slow (slow.csv) at 8.5 Hz (68 samples over 7.88 s)"
    assert sigma["sample_rate_mismatch"].startswith(f"{slow} against v.noise in fast (fast.csv) ")
    assert "at 200 Hz (1601 samples over 8 s): 23.5× apart" in sigma["sample_rate_mismatch"]
    assert "σ differs by bandwidth (up to 4.9×)" in sigma["sample_rate_mismatch"]
    # An exact model's σ still differs by σ·sqrt(1/(2·67) + 1/(2·1600)) ≈ 8.8 % of σ > 5 %.
    expected = SIGMA * math.sqrt(0.5 / 67 + 0.5 / 1600)
    assert sigma["few_samples"].startswith(f"σ of {slow} against 1601 samples in v.noise in fast")
    error = float(sigma["few_samples"].split("differ by ")[1].split(" ")[0])
    assert error == pytest.approx(expected, rel=0.15)  # the sample σ, not SIGMA itself
    # A mean is unbiased at any rate and its σ is 0 here: nothing to warn about.
    assert _warnings(report, "level_mean") == {}
    # The slow log's own grid takes the fast log's point samples, as a logger would; the
    # slow curve interpolated onto the fast grid lacks everything above 4.25 Hz.
    assert _warnings(report, "wave_on_the_slow_grid") == {}
    interpolated = _warnings(report, "slow_wave_on_the_fast_grid")["sample_rate_mismatch"]
    assert interpolated.startswith("v.wave in slow (slow.csv) at 8.5 Hz (68 samples")
    assert "against the comparison grid t_1 … t_n at 200 Hz (1601 samples over 8 s)" in (
        interpolated
    )
    assert "detail above 4.25 Hz is missing from it" in interpolated
    # The HTML lists them near the top and marks the tests.
    assert "What this report could not compare" in html
    assert html.index("What this report could not compare") < html.index("<h2>Tests</h2>")
    assert 'id="test-noise_sigma">noise_sigma — performance: std [] <span class="warn">⚠ 2' in html
    assert len(report["warnings"]) == 3


MISSING = """
[[tests]]
name = "level"
kind = "performance"
parameter = "mean"
signal = "v.level"
segment_s = [1.0, 9.0]
compare = ["sim_low"]

[[tests]]
name = "thrust"
kind = "performance"
parameter = "mean"
signal = "v.thrust"
segment_s = [1.0, 9.0]
"""


def test_a_missing_topic_is_listed_as_not_scored_and_left_out_of_the_indices(tmp_path):
    _log(tmp_path / "real.csv", FAST_HZ, seed=1, level=10.0, thrust=0.5)
    _log(tmp_path / "sim.csv", FAST_HZ, seed=2, level=10.2)  # this sim logs no thrust
    _log(tmp_path / "sim_low.csv", FAST_HZ, seed=3)  # and this one no level either
    logs = 'real = "real.csv"\nsim = "sim.csv"\nsim_low = "sim_low.csv"'
    code, report, html = _report(_plan(tmp_path, MISSING, logs))
    thrust = report["tests"][1]
    assert (thrust["name"], thrust["scored"], thrust["eta"]) == ("thrust", False, None)
    assert thrust["not_scored"]["kind"] == "missing_topic"
    assert (
        "sim.csv: no field 'thrust' (signal 'v.thrust'); fields: level, noise, wave"
        in (thrust["not_scored"]["message"])
    )
    assert thrust["not_scored"]["message"].endswith("; not scored")
    # One of two performance tests is scored: half, enough for a verdict over it alone.
    level = _eta(0.2, 0.5)  # p_e = 10, p_s = 10.2, ε_p = 0.05 · 10
    assert report["summary"]["scored"] == 1
    assert report["summary"]["not_scored"] == ["thrust"]
    assert report["summary"]["eta_all"] == pytest.approx(level, rel=1e-9)
    assert report["summary"]["eta_min"] == pytest.approx(level, rel=1e-9)
    assert code == 0  # η_min ≥ ε_min = 0.5
    # The compared sim without the topic loses its row, and says so; the test is scored.
    left_out = _warnings(report, "level")["missing_topic"]
    assert "sim_low.csv: no field 'level'" in left_out
    assert left_out.endswith("; compared sim 'sim_low' left out")
    assert [row["role"] for row in report["tests"][0]["rows"]] == ["sim"]
    assert "1 of 2 tests not scored" in html
    assert 'thrust — performance: <span class="fail">not scored</span> (missing_topic)' in html
    # A caller of assess() that needs every number still gets the error, as before.
    with pytest.raises(CredibilityError, match=r"^test 'thrust': .*no field 'thrust'"):
        assess(load_plan(tmp_path / "plan.toml"))


EPSILON = """
[[tests]]
name = "flat"
kind = "time"
signal = "v.level"
segment_s = [1.0, 9.0]

[[tests]]
name = "near_flat"
kind = "time"
signal = "v.noise"
segment_s = [1.0, 9.0]

[[tests]]
name = "wave"
kind = "time"
signal = "v.wave"
segment_s = [1.0, 9.0]
"""


def test_a_threshold_of_zero_is_not_scored_and_one_below_the_noise_is_flagged(tmp_path):
    """A constant real curve makes ε_t = K_p·range = 0 (η undefined): not scored. Pure
    noise makes ε_t ≈ K_p·6σ, below the noise σ itself: scored, but flagged."""
    _log(tmp_path / "real.csv", FAST_HZ, seed=1, level=3.0)
    _log(tmp_path / "sim.csv", FAST_HZ, seed=2, level=3.0)
    code, report, _ = _report(_plan(tmp_path, EPSILON))
    flat = report["tests"][0]
    assert flat["scored"] is False
    assert flat["not_scored"]["kind"] == "unscorable_epsilon"
    assert flat["not_scored"]["message"] == (
        "ε_t = 0 (K_p·(max y_e − min y_e)) is not > 0, so η is undefined; give the test a "
        "threshold; not scored"
    )
    near_flat = report["tests"][1]
    assert near_flat["scored"] is True
    assert near_flat["noise_floor"] == pytest.approx(SIGMA, rel=0.1)
    warning = _warnings(report, "near_flat")["epsilon_below_noise"]
    assert warning.startswith(f"ε_t = {near_flat['threshold']:.3g} (K_p·(max y_e − min y_e)) ")
    assert f"is below the real log's noise floor {near_flat['noise_floor']:.3g} " in warning
    assert "even an exact model would score below the pass mark" in warning
    assert _warnings(report, "wave") == {}
    # Two of three time tests scored; η_min is the noise-bound test's.
    assert report["summary"]["eta_min"] == pytest.approx(near_flat["eta"], rel=1e-12)
    assert code == 1


EXIT = """
[[tests]]
name = "level"
kind = "performance"
parameter = "mean"
signal = "v.level"
segment_s = [1.0, 9.0]

[[tests]]
name = "wave"
kind = "time"
signal = "v.wave"
segment_s = [1.0, 9.0]
"""


@pytest.fixture
def exit_logs(tmp_path):
    _log(tmp_path / "real.csv", FAST_HZ, seed=1, level=10.0)
    _log(tmp_path / "sim.csv", FAST_HZ, seed=1, level=10.0)  # the same flight: η = 1
    _log(tmp_path / "other.csv", FAST_HZ, seed=1, level=12.0)
    _log(tmp_path / "foreign.csv", FAST_HZ, seed=1)  # logs none of the plan's topics
    return tmp_path


@pytest.mark.parametrize(
    ("options", "code", "outcome"),
    [
        ([], 0, "pass"),
        (["--log", "sim=other.csv"], 1, "fail"),
        (["--log", "sim=foreign.csv"], 3, "could not be scored"),
    ],
)
def test_exit_codes_tell_pass_fail_and_not_scored_apart(exit_logs, options, code, outcome):
    options = [o if "=" not in o else o.replace("=", f"={exit_logs}/") for o in options]
    got, report, html = _report(_plan(exit_logs, EXIT), *options)
    assert got == code
    assert report["summary"]["exit_code"] == code
    assert report["summary"]["outcome"] == outcome
    if code == 3:
        assert report["summary"]["eta_all"] is None
        assert report["summary"]["unscorable_reason"] == (
            "no performance test (of 1) could be scored: η̄_p is undefined"
        )
        assert {w["kind"] for w in report["warnings"]} == {"missing_topic"}
        assert "Could not be scored: no performance test (of 1) could be scored" in html


def test_exit_code_2_for_input_that_cannot_be_read(exit_logs, capsys):
    plan, missing = _plan(exit_logs, EXIT), exit_logs / "missing.csv"
    assert main(["report", plan, "--log", f"sim={missing}", "--out", str(exit_logs)]) == 2
    last = capsys.readouterr().err.splitlines()[-1]
    assert last == f"credibility: error: {missing}: log file not found"


def test_report_help_lists_the_exit_codes(capsys):
    with pytest.raises(SystemExit) as done:
        main(["report", "--help"])
    assert done.value.code == 0
    help_text = capsys.readouterr().out
    for line in ("0  pass", "1  fail", "2  bad input", "3  could not be scored"):
        assert line in help_text
