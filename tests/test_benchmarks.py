"""``python -m benchmarks``: the figures file keeps every module's last figures, and
``--compare`` sets two of them side by side; the lockstep-exchange anchor's two processes
answer each other (the benchmarks themselves run in ``make bench``)."""

import json

import pytest

from benchmarks.__main__ import main, merged_record
from benchmarks.figures import Figure
from benchmarks.lockstep_exchange import MODES, exchange_us


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
