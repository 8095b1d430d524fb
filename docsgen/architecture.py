"""The architecture map, drawn from the import contracts ``make lint`` checks.

``[tool.importlinter]`` in ``pyproject.toml`` is the one place that says which package may
import which: its ``forbidden`` contracts order the top-level packages, its ``layers``
contracts the parts inside one. The map on the architecture page is rendered from them,
each part linked to its API page (and to its guide, :data:`GUIDES`), so a module moved or
a layer added changes the map at the next build.
"""

from __future__ import annotations

import ast
import logging
import posixpath
from pathlib import Path
from typing import Any

from docsgen import ROOT, packages, pyproject, table_cell
from docsgen.api_reference import page_path

log = logging.getLogger("mkdocs.plugins.docsgen")

#: The user guide of each part, by module prefix (the longest prefix that matches wins).
#: A prefix that names no module fails the strict build, so a rename cannot leave it stale.
GUIDES: dict[str, tuple[str, ...]] = {
    "hil_config": ("design/configuration.md",),
    "quad_model": ("guide/vehicle-model.md",),
    "fpga_hdl": ("guide/sensor-chips.md",),
    "fpga_hdl.synth": ("guide/synthesis.md",),
    "rig": ("guide/closed-loop.md",),
    "rig.scenarios": ("guide/closed-loop.md", "reference/configuration/scenario.md"),
    "rig.autopilots": ("guide/reference-autopilot.md", "guide/px4.md"),
    "rig.replay": ("guide/replay.md", "tutorials/replay-a-log.md"),
    "rig.identify": ("guide/identify.md", "guide/vehicle-from-log.md"),
    "rig.study": ("tutorials/study-your-log.md",),
    "rig.campaign": ("guide/campaigns.md", "tutorials/run-a-campaign.md"),
    "rig.view": ("tutorials/fly-the-demo.md",),
    "px4_logs": ("guide/replay.md", "guide/identify.md"),
    "credibility": ("guide/credibility.md",),
    "credibility.autoplan": ("guide/plan-from-a-log.md",),
}


def render_map(page: str, root: Path = ROOT) -> str:
    """The map as Markdown for the page at site path ``page`` (its links are relative)."""
    contracts = pyproject()["tool"]["importlinter"]["contracts"]
    known = _modules(root)
    for prefix in GUIDES:
        if prefix not in known:
            log.warning("docsgen.architecture.GUIDES names %s, which is no module", prefix)
    lines = [
        "### Packages",
        "",
        "Top to bottom: each package imports only those in the rows below it "
        "(`make lint` checks it with import-linter).",
        "",
        "| layer | package | what it is | guide | imports none of |",
        "|---|---|---|---|---|",
    ]
    forbidden = _forbidden(contracts)
    names = packages()
    ranks = sorted({len(forbidden.get(name, ())) for name in names})
    for layer, rank in enumerate(ranks):
        for name in [n for n in names if len(forbidden.get(n, ())) == rank]:
            banned = ", ".join(f"`{other}`" for other in forbidden.get(name, ()))
            lines.append(
                f"| {len(ranks) - layer} | {_api_link(page, name)} | {_summary(root, name)} "
                f"| {_guide_links(page, name)} | {banned} |"
            )
    for contract in contracts:
        if contract.get("type") != "layers":
            continue
        lines += ["", f"### {contract['name']}", ""]
        lines += ["| layer | part | what it is | guide |", "|---|---|---|---|"]
        for depth, layer in enumerate(contract["layers"]):
            for name in (part.strip() for part in layer.split("|")):
                lines.append(
                    f"| {len(contract['layers']) - depth} | {_api_link(page, name)} "
                    f"| {_summary(root, name)} | {_guide_links(page, name)} |"
                )
    return "\n".join(lines) + "\n"


def _forbidden(contracts: list[dict[str, Any]]) -> dict[str, list[str]]:
    found: dict[str, list[str]] = {}
    for contract in contracts:
        if contract.get("type") == "forbidden":
            for source in contract["source_modules"]:
                found.setdefault(source, []).extend(contract["forbidden_modules"])
    return found


def _modules(root: Path) -> set[str]:
    from docsgen.api_reference import modules

    return {module for package in packages() for module in modules(root, package)}


def _link(page: str, target: str) -> str:
    return posixpath.relpath(target, posixpath.dirname(page))


def _api_link(page: str, module: str) -> str:
    return f"[`{module}`]({_link(page, page_path(module))})"


def _guide_links(page: str, module: str) -> str:
    prefixes = [p for p in GUIDES if module == p or module.startswith(p + ".")]
    if not prefixes:
        return ""
    guides = GUIDES[max(prefixes, key=len)]
    return ", ".join(f"[{_title(guide)}]({_link(page, guide)})" for guide in guides)


def _title(guide: str) -> str:
    return Path(guide).stem.replace("-", " ")


def _summary(root: Path, module: str) -> str:
    """The first sentence of the module's docstring, as Markdown."""
    path = root.joinpath(*module.split("."))
    source = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
    docstring = ast.get_docstring(ast.parse(source.read_text(encoding="utf-8"))) or ""
    paragraph = docstring.split("\n\n")[0]
    from docsgen.griffe_rst import markdown_roles

    text = markdown_roles(" ".join(paragraph.split())).replace("``", "`")
    sentence, dot, _ = text.partition(". ")
    return table_cell(sentence.rstrip(":") + (dot.strip() if dot else ""))
