"""What a plan declares not scorable reaches the report (JSON, HTML, the command line), and
``credibility summary`` puts several reports into one table per real log."""

import json
from pathlib import Path

import pytest

from credibility.cli import main
from credibility.errors import CredibilityError
from credibility.plan import load_plan

REPO = Path(__file__).resolve().parents[2]
QUAD_LOG = REPO / "data/flight_logs/px4_quad4001_v6c_stab_hover_2026-03-09.ulg"

PLAN = f"""
[plan]
name = "rest only"
[logs]
real = "{QUAD_LOG}"
sim = "{QUAD_LOG}"

[[tests]]
name = "gyro_x_rest"
kind = "performance"
parameter = "std"
signal = "sensor_combined.gyro_rad[0]"
segment_s = [105.2, 106.9]
segment_sim_s = [107.0, 108.7]

[[tests]]
name = "gyro_x_absent"
kind = "performance"
parameter = "std"
signal = "no_such_topic.x"
segment_s = [105.2, 106.9]

[[not_scorable]]
name = "position"
kind = "time"
reason = "no GNSS in the log"
"""


@pytest.fixture
def plan_path(tmp_path) -> Path:
    path = tmp_path / "rest_only.toml"
    path.write_text(PLAN)
    return path


def test_not_scorable_tests_reach_every_output(plan_path, tmp_path, capsys):
    """Declared: listed with its reason in the JSON summary, the HTML and on stderr, in no
    index; a test that failed to score is listed apart, with the reader's reason."""
    assert main(["report", str(plan_path), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert "not scorable from these logs: position (time): no GNSS in the log" in err
    report = json.loads((tmp_path / "out/rest_only.json").read_text())
    summary = report["summary"]
    assert summary["not_scorable"] == [
        {"name": "position", "kind": "time", "reason": "no GNSS in the log"}
    ]
    assert summary["not_scored"] == ["gyro_x_absent"]
    assert summary["scored"] == 1
    html = (tmp_path / "out/rest_only.html").read_text()
    assert "What these logs cannot score" in html
    assert "no GNSS in the log" in html


def test_summary_tables_each_log_with_what_it_could_not_score(plan_path, tmp_path, capsys):
    main(["report", str(plan_path), "--out", str(tmp_path / "out")])
    capsys.readouterr()
    table = tmp_path / "summary.md"
    report = tmp_path / "out/rest_only.json"
    assert main(["summary", str(report), "--out", str(table)]) == 0
    printed = capsys.readouterr().out
    assert printed == table.read_text()
    row = next(line for line in printed.splitlines() if line.startswith(f"| {QUAD_LOG.name}"))
    cells = [cell.strip() for cell in row.strip("|").split("|")]
    assert cells[1:4] == ["rest only", "fail (exit 1)", "1 of 2"]
    assert cells[-2:] == ["1", "1"]  # one not scored, one not scorable
    assert "- not scorable (time): position: no GNSS in the log" in printed
    assert "- not scored: gyro_x_absent: " in printed


def test_a_bad_report_or_a_duplicate_name_is_one_line(plan_path, tmp_path, capsys):
    junk = tmp_path / "junk.json"
    junk.write_text("[1, 2]")
    assert main(["summary", str(junk)]) == 2
    err = capsys.readouterr().err.strip()
    assert (
        err == f"credibility: error: {junk}: not a credibility report (no plan, summary and logs)"
    )
    older = tmp_path / "older.json"
    older.write_text(json.dumps({"plan": {}, "logs": [], "summary": {"eta_all": 0.5}}))
    assert main(["summary", str(older)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"credibility: error: {older}: the report's summary has no eta_min, ")
    assert err.endswith("(written by an older credibility: report it again)")
    plan_path.write_text(PLAN.replace('name = "position"', 'name = "gyro_x_rest"'))
    with pytest.raises(CredibilityError, match=r"gyro_x_rest.*duplicate test names") as error:
        load_plan(plan_path)
    assert "\n" not in str(error.value)
