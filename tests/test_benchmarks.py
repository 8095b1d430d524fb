"""``python -m benchmarks``: the figures file keeps every module's last figures, and
``--compare`` sets two of them side by side; the lockstep-exchange anchor's two processes
answer each other (the benchmarks themselves run in ``make bench``)."""

import json
import math
from pathlib import Path

import pytest

from benchmarks.__main__ import main, merged_record
from benchmarks.bench_px4 import lowest_share
from benchmarks.figures import Figure, chips_detail, lowest_of
from benchmarks.lockstep_exchange import MODES, exchange_us
from fpga_hdl.cosim.native import CallCost
from rig.lockstep.loop import FrameBudget, RunResult
from rig.mavlink.simulator_link import LinkStats


def _record(path, modules):
    path.write_text(json.dumps({"modules": modules}))
    return path


def _module(commit, *figures):
    return {"measured": "2026-11-27T00:00:00+00:00", "commit": commit, "cpus": 2,
            "load_1min": 0.1, "figures": [vars(f) for f in figures]}  # fmt: skip


def test_a_run_of_some_modules_keeps_the_others():
    previous = {"bench_quad_model": _module("aaa", Figure("batch", 100.0, "vehicle-s/s"))}
    record = merged_record(
        previous, {"bench_px4": [Figure("PX4 + rig", 7.0, "× real time", "≥ 9.6×")]},
        {"measured": "now", "commit": "bbb", "cpus": 2, "load_1min": 1.0},
    )  # fmt: skip
    modules = record["modules"]
    assert modules["bench_quad_model"] == previous["bench_quad_model"]
    assert modules["bench_px4"]["commit"] == "bbb"
    assert modules["bench_px4"]["figures"] == [
        {"name": "PX4 + rig", "value": 7.0, "unit": "× real time", "goal": "≥ 9.6×", "detail": ""}
    ]


def test_compare_sets_two_commits_side_by_side(tmp_path, capsys):
    before = _record(tmp_path / "a.json", {
        "bench_rig": _module("aaa", Figure("RTL 1 kHz", 1.0, "× real time", "≥ 2×"),
                             Figure("gone", 3.0, "MiB")),
    })  # fmt: skip
    after = _record(tmp_path / "b.json", {
        "bench_rig": _module("bbb", Figure("RTL 1 kHz", 1.5, "× real time", "≥ 2×"),
                             Figure("new", 2.0, "MiB")),
    })  # fmt: skip
    assert main(["--compare", str(before), str(after)]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if "RTL 1 kHz" in line)
    assert [cell.strip() for cell in row.split("│")[2:7]] == [
        "RTL 1 kHz",
        "1.00",
        "1.50",
        "1.50",
        "× real time",
    ]
    assert "—" in next(line for line in out.splitlines() if "gone" in line)
    assert "before: aaa" in out
    assert "after: bbb" in out


def test_compare_says_in_one_line_what_is_wrong(tmp_path, capsys):
    assert main(["--compare"]) == 2
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2]")
    with pytest.raises(SystemExit, match=r"bad.json: not a figures file"):
        main(["--compare", str(bad), str(bad)])


@pytest.mark.parametrize("mode", MODES)
def test_the_lockstep_exchange_alone_answers_every_frame(mode):
    """The floor's two processes trade every frame (a peer that missed one would leave the
    timing side waiting and fail on the timeout); the time is a benchmark's, not checked."""
    assert exchange_us(300, mode) > 0


def test_the_lockstep_exchange_refuses_an_unknown_mode():
    with pytest.raises(ValueError, match=r"mode must be one of .*not 'udp'"):
        exchange_us(10, "udp")


def test_repeated_runs_count_the_lowest_and_show_the_spread():
    runs = [Figure("RTL", value, "× real time", detail=f"run {value}") for value in (0.9, 0.7, 0.8)]
    figure = lowest_of(runs, "≥ 2×")
    assert (figure.value, figure.goal) == (0.7, "≥ 2×")
    assert figure.detail == "lowest of 3 runs (0.70, 0.80, 0.90); run 0.7"
    failed = Figure("RTL", float("nan"), "× real time", detail="failed: stalled")
    assert lowest_of([*runs, failed]) is failed  # a failure is never hidden by the others


def test_a_px4_goal_counts_the_lowest_round_against_its_own_anchor():
    """Each round's share is the rig over the anchor flown with it, not over the median
    anchor: the rounds' medians would read 8/10 = 80 % here."""
    rig = [Figure("PX4 + rig, TLM", value, "× real time") for value in (8.0, 6.0, 9.0)]
    anchors = [Figure("anchor", value, "× real time") for value in (10.0, 12.0, 9.0)]
    figure = lowest_share(rig, anchors, 0.8)
    assert (figure.name, figure.value, figure.goal) == (
        "PX4 + rig, TLM, share of the anchor",
        50.0,
        "≥ 80%",
    )
    assert figure.detail == ("lowest of 3 rounds (rig / anchor): 50 % (6.00× / 12.00×), "
                             "80 % (8.00× / 10.00×), 100 % (9.00× / 9.00×)")  # fmt: skip
    failed = Figure("anchor", float("nan"), "× real time", detail="failed: stalled")
    assert math.isnan(lowest_share(rig, [*anchors[:2], failed], 0.8).value)


def test_the_chips_budget_is_per_frame_and_most_expensive_first():
    costs = (
        CallCost("I2C mag", 50, 7_600, "system", 0.15),
        CallCost("SPI imu", 1000, 249_000, "system", 0.25),
        CallCost("SPI flow", 0, 0, "system", 0.0),  # never called over the frames
    )
    result = RunResult(Path("r"), Path("r/rig.ulg"), None, 1.0, 1.2, 1000, LinkStats(),
                       FrameBudget(*[0.0] * 8), chip_costs=costs)  # fmt: skip
    assert chips_detail(result) == (
        "chips per frame: SPI imu 250 µs / 249 system cycles (1004 ns each) · "
        "I2C mag 150 µs / 8 system cycles (19737 ns each)"
    )
