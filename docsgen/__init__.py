"""The documentation site's generated pages (``make docs``), and ``make results``.

Everything a page would otherwise repeat by hand is read from where it is defined, so that
moving a module costs the docs nothing: the packages and their layers from
``pyproject.toml`` (``[tool.importlinter]``), the command lines from the parsers of
``[project.scripts]``, the configuration files from the JSON Schema ``rig schema`` writes,
the API from the docstrings, and the results from the JSON that ``make bench`` and
``make credibility`` write (copied into ``docs/results/`` by ``make results``).

Every renderer is a pure function from data to Markdown text, so a test can hold it to a
known input; :mod:`docsgen.pages` is the one place that writes them into the site.
"""

from __future__ import annotations

import tomllib
from functools import cache
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
RESULTS = DOCS / "results"


@cache
def pyproject() -> dict[str, Any]:
    """The project's ``pyproject.toml``: the one list of packages, layers and commands."""
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def packages() -> list[str]:
    """The project's top-level packages, in the order the layer contracts list them."""
    return list(pyproject()["tool"]["importlinter"]["root_packages"])


def prose(text: object) -> str:
    """Plain text as Markdown that shows it as written: ``<name>`` outside code spans is
    escaped, so it is not taken for an HTML tag and dropped."""
    parts = str(text).split("`")
    for index in range(0, len(parts), 2):  # the even parts lie outside code spans
        parts[index] = parts[index].replace("<", "&lt;").replace(">", "&gt;")
    return "`".join(parts)


def table_cell(text: object) -> str:
    """Text that stays in one Markdown table cell (no pipe, no line break)."""
    return " ".join(str(text).split()).replace("|", "\\|")
