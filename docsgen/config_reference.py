"""The configuration-file reference, rendered from the JSON Schema ``rig schema`` writes.

The schema is the one the loaders check (:mod:`hil_config`), so each table on these pages
lists exactly the keys a file may have: type and bounds, default, and what the field or
table says of itself.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import json
import tempfile
from pathlib import Path
from typing import Any

from docsgen import prose, pyproject, table_cell

#: What each kind of file is, for its page's first line (a kind not named here still gets
#: its page, from the schema alone).
KIND_TITLES = {
    "scenario": "Scenario files",
    "vehicle": "Vehicle files",
    "campaign": "Campaign files",
    "plan": "Credibility plans",
}

Schema = dict[str, Any]


def schemas() -> dict[str, Schema]:
    """Each file kind's JSON Schema, written by ``rig schema`` into a scratch folder."""
    target = pyproject()["project"]["scripts"]["rig"]
    module, _, function = target.partition(":")
    main = getattr(importlib.import_module(module), function)
    with tempfile.TemporaryDirectory() as folder, contextlib.redirect_stderr(io.StringIO()):
        if main(["schema", "--out", folder]) != 0:
            raise RuntimeError("rig schema failed")
        return {
            path.name.removesuffix(".schema.json"): json.loads(path.read_text("utf-8"))
            for path in sorted(Path(folder).glob("*.schema.json"))
        }


def render_index(kinds: list[str]) -> str:
    """The section's first page: one line per kind of file."""
    lines = [
        "# Configuration files",
        "",
        "Every configuration file is TOML, checked on loading against typed tables "
        "([why](../../design/configuration.md)). A mistake fails with one line naming the "
        "file, the key, the value and what was expected. These pages are generated from the "
        "JSON Schema that `rig schema` writes; a file that starts with "
        "`#:schema schemas/scenario.schema.json` is completed and checked by TOML editors "
        "that read JSON Schema (Taplo, VS Code's Even Better TOML).",
        "",
        "| file | page |",
        "|---|---|",
    ]
    lines += [f"| {kind} | [{KIND_TITLES.get(kind, kind)}]({kind}.md) |" for kind in kinds]
    return "\n".join(lines) + "\n"


def render_kind(kind: str, schema: Schema) -> str:
    """One kind's page: its top table, then every table it refers to, in order of use."""
    definitions = schema.get("$defs", {})
    lines = [f"# {KIND_TITLES.get(kind, kind)}", ""]
    top = dict(schema, title=schema.get("title", kind))
    for name, table in _tables(top, definitions):
        lines += _table(name, table, name == top["title"])
    return "\n".join(lines) + "\n"


def _tables(top: Schema, definitions: dict[str, Schema]) -> list[tuple[str, Schema]]:
    """The top table and each definition reachable from it, breadth first."""
    order: list[tuple[str, Schema]] = [(top["title"], top)]
    seen = {top["title"]}
    index = 0
    while index < len(order):
        for name in _references(order[index][1]):
            if name not in seen and name in definitions:
                seen.add(name)
                order.append((name, definitions[name]))
        index += 1
    return order


def _references(node: Any) -> list[str]:
    if isinstance(node, dict):
        found = [node["$ref"].rpartition("/")[2]] if "$ref" in node else []
        for key, value in node.items():
            if key not in ("default", "$defs"):
                found += _references(value)
        return found
    if isinstance(node, list):
        return [name for item in node for name in _references(item)]
    return []


def _table(name: str, table: Schema, top: bool) -> list[str]:
    lines = [f"## {'File' if top else name}" + ("" if top else f" {{ #{_anchor(name)} }}"), ""]
    if top and table.get("title"):
        lines += [f"Top table: `{table['title']}`.", ""]
    if table.get("description"):
        lines += [prose(_prose(table["description"])), ""]
    if "enum" in table:
        lines += ["One of " + ", ".join(f"`{json.dumps(v)}`" for v in table["enum"]) + ".", ""]
        return lines
    properties = table.get("properties", {})
    if not properties:
        return lines
    required = set(table.get("required", []))
    lines += ["| key | type | default | description |", "|---|---|---|---|"]
    for key, field in properties.items():
        default = "required" if key in required else _default(field)
        lines.append(
            f"| `{key}` | {_type(field)} | {default} "
            f"| {prose(table_cell(_prose(field.get('description', ''))))} |"
        )
    return [*lines, ""]


def _anchor(name: str) -> str:
    return name.lower()


def _prose(text: str) -> str:
    """A docstring's reStructuredText as Markdown: ``x`` and :role:`x` as code."""
    text = text.replace("``", "`")
    for role in ("func", "class", "data", "mod", "meth", "attr", "exc"):
        text = text.replace(f":{role}:`", "`")
    return text


def _type(field: Schema) -> str:
    """A field's type as a reader spells it, with its bounds; tables link to their rows."""
    if "$ref" in field:
        name = field["$ref"].rpartition("/")[2]
        return f"[{name}](#{_anchor(name)})"
    if "const" in field:
        return f"`{json.dumps(field['const'])}`"
    if "enum" in field:
        return " \\| ".join(f"`{json.dumps(v)}`" for v in field["enum"])
    for union in ("anyOf", "oneOf"):
        if union in field:
            return " or ".join(_type(option) for option in field[union])
    kind = field.get("type", "any")
    if kind == "array":
        if "prefixItems" in field:
            return "[" + ", ".join(_type(item) for item in field["prefixItems"]) + "]"
        items = field.get("items")
        return f"array of {_type(items)}" if items else "array"
    if kind == "object" and "additionalProperties" in field:
        values = field["additionalProperties"]
        return f"table of {_type(values)}" if isinstance(values, dict) else "table"
    if kind == "null":
        return "none"
    bounds = [f"{symbol} {field[key]:g}" for key, symbol in _BOUNDS if key in field]
    if "minLength" in field:
        bounds.append("not empty" if field["minLength"] == 1 else f"≥ {field['minLength']} chars")
    return kind + (f" ({', '.join(bounds)})" if bounds else "")


_BOUNDS = (("exclusiveMinimum", ">"), ("minimum", "≥"), ("exclusiveMaximum", "<"),
           ("maximum", "≤"))  # fmt: skip


def _default(field: Schema) -> str:
    if "default" not in field:
        return ""
    value = field["default"]
    if isinstance(value, dict):
        return "its table's defaults"
    return f"`{table_cell(json.dumps(value, ensure_ascii=False))}`"
