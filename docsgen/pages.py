"""The generated pages, written into the site by mkdocs-gen-files during ``make docs``.

The one place that decides where each generated page goes; each page's text comes from a
renderer of :mod:`docsgen`.
"""

from __future__ import annotations

import sys
from pathlib import Path

import mkdocs_gen_files

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # docsgen, benchmarks

from docsgen import (
    DOCS,
    ROOT,
    api_reference,
    architecture,
    cli_reference,
    config_reference,
    packages,
    results,
)

#: The hand-written page that holds the map, and the line the map replaces.
ARCHITECTURE_PAGE = "design/architecture.md"
MAP_MARKER = "<!-- the architecture map: docsgen.architecture -->"


def write(path: str, text: str) -> None:
    with mkdocs_gen_files.open(path, "w") as page:
        page.write(text)


def generate() -> None:
    write("reference/cli.md", cli_reference.render_cli(cli_reference.parsers()))

    schemas = config_reference.schemas()
    write("reference/configuration/index.md", config_reference.render_index(list(schemas)))
    for kind, schema in schemas.items():
        write(f"reference/configuration/{kind}.md", config_reference.render_kind(kind, schema))

    modules = [m for package in packages() for m in api_reference.modules(ROOT, package)]
    for module in modules:
        write(api_reference.page_path(module), api_reference.render_module(module))
    write(f"{api_reference.API_DIR}/SUMMARY.md", api_reference.render_nav(modules))

    text = (DOCS / ARCHITECTURE_PAGE).read_text(encoding="utf-8")
    if MAP_MARKER not in text:
        raise SystemExit(f"docs/{ARCHITECTURE_PAGE} lost its line {MAP_MARKER}")
    write(ARCHITECTURE_PAGE, text.replace(MAP_MARKER, architecture.render_map(ARCHITECTURE_PAGE)))

    speed = results.render_speed(results.load_figures(), results.benchmark_modules())
    write("results/speed.md", speed)
    write("results/credibility.md", results.render_credibility(results.load_reports()))
    write("changelog.md", (ROOT / "CHANGELOG.md").read_text(encoding="utf-8"))


generate()
