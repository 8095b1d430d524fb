"""`credibility report --weights / --weight`: η_all's α from the command line, checked and
normalized, against eq. (overall) written out."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from credibility.cli import main

PLAN = """
[weights]
performance = 0.5
time = 0.5

[logs]
real = "real.csv"
sim = "sim.csv"

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


def _eta(e, eps):
    return 0.75 * eps / math.hypot(0.75 * eps, e)


# Closed forms: mean 10.5 vs 10 with ε_p = 0.5 → η_p; a 0.05 offset on a unit sine, ε_t = 0.1.
ETA_P = _eta(0.5, 0.5)
ETA_T = _eta(0.05, 0.1)


@pytest.fixture
def plan(tmp_path):
    t = np.arange(0.0, 10.0, 0.01)
    wave = np.sin(2 * np.pi * t)
    pd.DataFrame({"time_s": t, "v.level": 10.0, "v.wave": wave}).to_csv(
        tmp_path / "real.csv", index=False
    )
    pd.DataFrame({"time_s": t, "v.level": 10.5, "v.wave": wave + 0.05}).to_csv(
        tmp_path / "sim.csv", index=False
    )
    path = tmp_path / "plan.toml"
    path.write_text(PLAN)
    return path


def _report(plan, *options):
    out = plan.parent / "out"
    code = main(["report", str(plan), "--out", str(out), *options])
    return code, json.loads((out / "plan.json").read_text())


def test_plan_weights_without_options(plan):
    _, report = _report(plan)
    assert report["summary"]["eta_all"] == pytest.approx(
        math.sqrt(0.5 * ETA_P**2 + 0.5 * ETA_T**2), rel=1e-9
    )
    assert report["plan"]["weights_source"] == "plan"


def test_weights_are_normalized_and_noted(plan):
    _, report = _report(plan, "--weights", "1,3,0")
    assert report["plan"]["weights"] == {"performance": 0.25, "time": 0.75}
    assert report["plan"]["weights_source"] == (
        "command line --weights 1,3,0; normalized from sum 4"
    )
    assert report["summary"]["eta_all"] == pytest.approx(
        math.sqrt(0.25 * ETA_P**2 + 0.75 * ETA_T**2), rel=1e-9
    )
    html = (plan.parent / "out" / "plan.html").read_text()
    assert "normalized from sum 4" in html


def test_one_weight_overrides_the_plan_and_zero_leaves_a_kind_out(plan):
    _, report = _report(plan, "--weight", "time=1.5")
    assert report["plan"]["weights"] == pytest.approx({"performance": 0.25, "time": 0.75})
    _, report = _report(plan, "--weight", "time=0")
    assert report["summary"]["eta_all"] == pytest.approx(ETA_P, rel=1e-12)
    assert report["summary"]["eta_min"] == pytest.approx(min(ETA_P, ETA_T), rel=1e-12)
    assert (
        "time tests weighted 0, left out of η_all (still in η_min)"
        in (report["plan"]["weights_source"])
    )


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            ["--weights", "0.3,0.7"],
            "argument --weights: expects 3 numbers (performance,time,frequency)",
        ),
        (["--weights", "a,b,c"], "argument --weights: expects 3 numbers"),
        (["--weight", "time"], "argument --weight: expects KIND=NUMBER, got 'time'"),
        (["--weight", "tiem=0.5"], "--weight tiem=0.5: unknown kind 'tiem'"),
        (["--weights=-0.1,0.5,0"], "performance = -0.1 must be a finite number ≥ 0"),
        (["--weights", "0.5,nan,0"], "time = nan must be a finite number ≥ 0"),
        (["--weights", "0,0,0"], "the weights sum to 0; at least one must be > 0"),
        (["--weights", "0.3,0.3,0.4"], "frequency = 0.4 but the plan has no frequency tests"),
    ],
)
def test_bad_weights_give_one_line_and_exit_2(plan, capsys, options, message):
    try:
        code = main(["report", str(plan), "--out", str(plan.parent / "out"), *options])
    except SystemExit as exc:  # argparse's own usage errors exit from the parser
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.startswith("credibility: error: ")
    assert err.count("\n") == 1
