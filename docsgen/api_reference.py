"""The API reference: one page per module, found by walking the packages' folders.

Nothing lists modules by hand: a module moved or added is on its page at the next build,
and mkdocstrings (griffe, which reads the source without importing it) renders its
docstrings.
"""

from __future__ import annotations

from pathlib import Path

#: Where the API pages live in the site.
API_DIR = "reference/api"


def modules(root: Path, package: str) -> list[str]:
    """Every module of ``package`` under ``root`` (subpackages included), dotted, sorted so
    that a package comes before its modules."""
    found = []
    for path in sorted((root / package).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        if any(part.startswith((".", "_")) and part != "__init__" for part in parts):
            continue
        if not all((root.joinpath(*parts[:i]) / "__init__.py").is_file()
                   for i in range(1, len(parts))):  # fmt: skip
            continue  # a folder of scripts or data, not a subpackage
        found.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return sorted(set(found), key=lambda name: name.split("."))


def page_path(module: str) -> str:
    """The site path of a module's page (a package's page is its folder's index)."""
    return f"{API_DIR}/{module.replace('.', '/')}.md"


def render_module(module: str) -> str:
    """A module's page: mkdocstrings renders it from the source."""
    return f"::: {module}\n"


def render_nav(all_modules: list[str]) -> str:
    """The section's navigation (literate-nav's SUMMARY.md), nested as the packages are."""
    lines = []
    for module in all_modules:
        depth = module.count(".")
        target = page_path(module).removeprefix(API_DIR + "/")
        lines.append(f"{'    ' * depth}* [{module.rpartition('.')[2]}]({target})")
    return "\n".join(lines) + "\n"
