"""The documentation's generators: known input → expected Markdown, and the README's
promises (short, the two commands, links that resolve). ``make docs`` builds the site
itself with --strict, which fails on any broken link or reference."""

import argparse
import json
import posixpath
import re
from pathlib import Path

from docsgen import DOCS, ROOT, api_reference, architecture, cli_reference, config_reference
from docsgen import results as results_pages

FIGURES = {
    "modules": {
        "bench_quad_model": {
            "measured": "2026-11-29T01:02:03+00:00",
            "commit": "abc1234",
            "cpus": 2,
            "load_1min": 0.5,
            "figures": [
                {"name": "one vehicle", "value": 123.456, "unit": "× real time",
                 "goal": "≥ 100×", "detail": "5 kHz | RK4"},
                {"name": "did not finish", "value": float("nan"), "unit": "", "goal": "",
                 "detail": "see log"},
            ],
        }
    }
}  # fmt: skip

REPORT = {
    "package": "hil-rig credibility",
    "package_version": "0.1.0",
    "created_utc": "2026-11-29T00:00:00+00:00",
    "commit": "def5678",
    "plan": {"path": "/somewhere/plans/demo.toml", "sha256": "00", "name": "Demo plan",
             "description": "", "pass_mark": 0.6, "eps_min": 0.6, "weights": {}, "text": "x"},
    "logs": [
        {"role": "real", "path": "/elsewhere/real.ulg", "sha256": "11", "format": "ulog",
         "warnings": [], "provenance": {"firmware": "PX4 v1.17", "replay": None}},
        {"role": "sim", "path": "/elsewhere/runs/rig.ulg", "sha256": "22", "format": "ulog",
         "warnings": [], "provenance": {"firmware": None, "replay": None}},
    ],
    "summary": {"outcome": "fail", "exit_code": 1, "scored": 1, "tests": 2, "eta_all": 0.5,
                "eta_min": 0.25, "means": {"performance": 0.5}, "not_scored": ["b"],
                "unscorable_reason": None, "not_scorable": []},
    "tests": [
        {"name": "a", "kind": "performance", "eta": 0.25, "passes_pass_mark": False,
         "rows": [1, 2, 3]},
        {"name": "b", "kind": "time", "not_scored": {"reason": "short_signal",
                                                     "message": "log too short"}},
    ],
}  # fmt: skip


def test_the_speed_page_shows_each_figure_with_its_stamp():
    page = results_pages.render_speed(FIGURES)
    assert "## quad_model" in page
    assert "Measured 2026-11-29T01:02:03+00:00 at commit `abc1234` on 2 CPUs, load 0.5" in page
    assert "| one vehicle | 123 | × real time | ≥ 100× | 5 kHz \\| RK4 |" in page
    assert "| did not finish | — |  |  | see log |" in page
    page = results_pages.render_speed(FIGURES, ["bench_px4", "bench_quad_model"])
    assert "Not recorded yet: px4 (`python -m benchmarks NAME`)." in page


def test_without_figures_the_speed_page_says_so_and_how_to_record_them():
    page = results_pages.render_speed(None)
    assert "No speed figures have been recorded yet." in page
    assert "`make bench` then `make results`" in page
    assert "|" not in page  # no table, no number


def test_the_credibility_page_shows_the_summary_the_stamp_and_each_test():
    page = results_pages.render_credibility({"demo": results_pages.slim_report(REPORT)})
    assert "| real.ulg | Demo plan | fail (exit 1) | 1 of 2 | 50.0% | 25.0% |" in page
    assert "scored 2026-11-29T00:00:00+00:00 at commit `def5678`" in page
    assert "| a | performance | 0.250 | no |" in page
    assert "| b | time | — | not scored: log too short |" in page
    assert "/elsewhere" not in page
    assert "/somewhere" not in page


def test_without_reports_the_credibility_page_says_so():
    page = results_pages.render_credibility({})
    assert "No credibility results have been recorded yet." in page


def test_make_results_records_figures_whole_and_reports_slim(tmp_path):
    bench = tmp_path / "figures.json"
    bench.write_text(json.dumps(FIGURES))
    reports = tmp_path / "reports"
    (reports / "demo_px4").mkdir(parents=True)
    (reports / "demo_px4" / "demo.json").write_text(json.dumps(REPORT))
    out = tmp_path / "results"
    (out / "credibility").mkdir(parents=True)
    (out / "credibility" / "gone.json").write_text("{}")  # a report no longer made
    written = results_pages.record(bench, reports, out)
    assert sorted(p.relative_to(out).as_posix() for p in written) == [
        "bench/figures.json", "credibility/demo_px4.json"
    ]  # fmt: skip
    recorded = json.loads((out / "credibility" / "demo_px4.json").read_text())
    assert recorded["commit"] == "def5678"
    assert [log["path"] for log in recorded["logs"]] == ["real.ulg", "rig.ulg"]
    assert "rows" not in recorded["tests"][0]
    assert "text" not in recorded["plan"]
    assert not (out / "credibility" / "gone.json").exists()
    assert results_pages.load_reports(out).keys() == {"demo_px4"}


def test_the_cli_reference_lists_subcommands_and_arguments():
    parser = argparse.ArgumentParser(prog="tool", description="Does things.")
    commands = parser.add_subparsers(dest="command")
    go = commands.add_parser("go", description="Go somewhere.", help="go")
    go.add_argument("where", help="the place")
    go.add_argument("--speed", type=float, default=1.5, help="how fast")
    go.add_argument("--mode", choices=["a", "b"], default="a", help="which | way")
    go.add_argument("--force", action="store_true", help="overwrite")
    page = cli_reference.render_cli({"tool": parser})
    assert "## `tool`" in page
    assert "### `tool go`" in page
    assert "Go somewhere." in page
    assert "| `where` | the place |  |  |" in page
    assert "| `--speed SPEED` | how fast |  | `1.5` |" in page
    assert "| `--mode MODE` | which \\| way | `a`, `b` | `a` |" in page
    assert "| `--force` | overwrite |  |  |" in page


def test_every_console_script_has_a_parser_for_the_reference():
    found = cli_reference.parsers()
    assert {"rig", "credibility"} <= found.keys()
    for parser in found.values():
        assert parser.description
        assert not parser.description.startswith("``")


def test_the_configuration_reference_renders_fields_types_and_defaults():
    schema = {
        "title": "Thing",
        "type": "object",
        "properties": {
            "name": {"type": "string", "minLength": 1},
            "rate_hz": {"type": "integer", "exclusiveMinimum": 0, "default": 50,
                        "description": "how often"},
            "part": {"$ref": "#/$defs/Part"},
        },
        "required": ["name"],
        "$defs": {"Part": {"type": "object", "description": "A part.",
                           "properties": {"kind": {"enum": ["x", "y"]}}}},
    }  # fmt: skip
    page = config_reference.render_kind("thing", schema)
    assert "| `name` | string (not empty) | required |  |" in page
    assert "| `rate_hz` | integer (> 0) | `50` | how often |" in page
    assert "| `part` | [Part](#part) |  |  |" in page
    assert "## Part { #part }" in page
    assert '| `kind` | `"x"` \\| `"y"` |' in page


def test_api_pages_are_found_by_walking_the_package(tmp_path):
    for path in ("pkg/__init__.py", "pkg/a.py", "pkg/sub/__init__.py", "pkg/sub/b.py",
                 "pkg/_private.py", "pkg/data/script.py"):  # fmt: skip
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text('"""Doc."""\n')
    modules = api_reference.modules(tmp_path, "pkg")
    assert modules == ["pkg", "pkg.a", "pkg.sub", "pkg.sub.b"]
    assert api_reference.page_path("pkg.sub.b") == "reference/api/pkg/sub/b.md"
    assert "    * [b](pkg/sub/b.md)" in api_reference.render_nav(modules)


def test_the_architecture_map_links_every_package_and_layer_to_existing_pages():
    page = "design/architecture.md"
    text = architecture.render_map(page)
    links = re.findall(r"\]\(([^)#]+)\)", text)
    known = {Path(page_path).as_posix() for page_path in _site_pages()}
    for link in links:
        target = posixpath.normpath(posixpath.join(posixpath.dirname(page), link))
        assert target in known, link
    for prefix in architecture.GUIDES:
        assert any(m == prefix or m.startswith(prefix + ".") for m in _modules()), prefix


def _modules() -> list[str]:
    from docsgen import packages

    return [m for package in packages() for m in api_reference.modules(ROOT, package)]


def _site_pages() -> set[str]:
    """The hand-written pages and the API pages the build generates."""
    pages = {p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")}
    pages |= {api_reference.page_path(m) for m in _modules()}
    pages |= {f"reference/configuration/{kind}.md" for kind in config_reference.KIND_TITLES}
    return pages


def test_the_readme_is_short_and_says_the_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 250
    for command in ("make hil-sim", "make test", "make docs"):
        assert command in text
    for link in re.findall(r"\]\(([^)#:]+)\)", text):
        assert (ROOT / link).exists(), link
    assert "session" not in text.lower()
    assert "../shared" not in text


def test_figures_from_a_busy_machine_say_so():
    busy = {"modules": {"bench_x": {**FIGURES["modules"]["bench_quad_model"], "load_1min": 9.5}}}
    assert "The machine was busy (load 9.5 on 2 CPUs)" in results_pages.render_speed(busy)
    assert "busy" not in results_pages.render_speed(FIGURES)


def test_angle_brackets_in_help_survive_markdown():
    parser = argparse.ArgumentParser(prog="tool", description="write <plan>.html")
    parser.add_argument("--out", help="folder (default runs/<name>; `a<b`)")
    page = cli_reference.render_cli({"tool": parser})
    assert "write &lt;plan&gt;.html" in page
    assert "default runs/&lt;name&gt;; `a<b`" in page
