"""One shape for every configuration file: typed tables, one TOML loader, one-line errors.

Each configuration file of the project (vehicle, scenario, credibility plan, campaign) is
declared as a tree of frozen dataclasses made with :func:`table`, whose field types carry
their bounds (:data:`Positive`, :data:`Vector3`, enums ...). pydantic v2 checks a parsed
TOML document against that tree (``docs/design/configuration.md`` says why pydantic): a
misspelt key, a wrong type, a value out of range or a NaN fails with one line that names
the file, the key, the value and what was expected. A check that spans several keys lives
in the table's ``__post_init__`` and raises :class:`FieldError` to name its key. Every
default is the dataclass field's default: defined once, shown in the JSON Schema
(:func:`json_schema`, written by ``rig schema``) that lets an editor complete and check
the files. A field's ``#:`` comment (its documentation, as Sphinx reads it) is its
description there, so an editor's hover and the configuration reference say what it is.

This package sits under every other one (quad_model and credibility included) and
imports none of them.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import re
import tomllib
from collections.abc import Mapping
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar, dataclass_transform

from pydantic import ConfigDict, Field, Strict, TypeAdapter, ValidationError

if TYPE_CHECKING:
    from typing_extensions import TypeForm

T = TypeVar("T")

#: A finite number; an integer in the file is read as a float. Strict: "5" is not 5.
Number = Annotated[float, Strict(), Field(allow_inf_nan=False)]
Positive = Annotated[Number, Field(gt=0)]
NonNegative = Annotated[Number, Field(ge=0)]
UnitInterval = Annotated[Number, Field(ge=0, le=1)]
Integer = Annotated[int, Strict()]
PositiveInteger = Annotated[Integer, Field(gt=0)]
NonNegativeInteger = Annotated[Integer, Field(ge=0)]
Text = Annotated[str, Strict(), Field(min_length=1)]
Vector3 = tuple[Number, Number, Number]


@dataclass_transform(frozen_default=True)
def table(cls: type[T] | None = None, *, kw_only: bool = False) -> Any:
    """A configuration table: a frozen dataclass whose unknown keys are refused.

    ``@table(kw_only=True)`` for tables that extend another (a command's ``at_s``).
    """

    def make(cls: type[T]) -> type[T]:
        made = dataclasses.dataclass(frozen=True, kw_only=kw_only)(cls)

        def describe(schema: dict[str, Any]) -> None:
            # Read only when a schema is made: finding a class's source parses its whole
            # module, which cost every process that imports the tables half a second.
            comments = {
                name: text
                for klass in reversed(made.__mro__)
                if dataclasses.is_dataclass(klass)
                for name, text in _field_comments(klass).items()
            }
            for name, prop in schema.get("properties", {}).items():
                if name in comments:
                    prop.setdefault("description", comments[name])

        made.__pydantic_config__ = ConfigDict(  # type: ignore[attr-defined]
            extra="forbid", json_schema_extra=describe
        )
        return made

    return make if cls is None else make(cls)


#: A field's line in a table's body (``name: type`` or ``name: type = default``).
_FIELD_LINE = re.compile(r"^(\w+)\s*:")


def _field_comments(cls: type) -> dict[str, str]:
    """Each field's ``#:`` comment lines in ``cls``'s own source, joined (none: no source).

    Why by hand: pydantic reads a field's docstring (``use_attribute_docstrings``) but not
    the ``#:`` comments above it, which the project's tables use as Sphinx does."""
    try:
        lines = inspect.getsource(cls).splitlines()
    except (OSError, TypeError):  # defined where no source is kept (an interactive session)
        return {}
    start = next((k for k, line in enumerate(lines) if line.lstrip().startswith("class ")), 0)
    body = lines[start + 1 :]
    indent = min((len(line) - len(line.lstrip()) for line in body if line.strip()), default=0)
    fields = {field.name for field in dataclasses.fields(cls)}
    comments: dict[str, str] = {}
    pending: list[str] = []
    for line in body:
        text = line.strip()
        if not text:  # a blank line ends a comment: it documents nothing below it
            pending = []
            continue
        if len(line) - len(line.lstrip()) != indent:
            continue  # inside a method or a continued line
        if text.startswith("#:"):
            pending.append(text[2:].strip())
            continue
        match = _FIELD_LINE.match(text)
        if match and match.group(1) in fields and pending:
            comments[match.group(1)] = " ".join(pending)
        pending = []
    return comments


class FieldError(ValueError):
    """A check across keys failed (raise it in a table's ``__post_init__``): names the key."""

    def __init__(self, key: str, value: Any, reason: str) -> None:
        super().__init__(f"{key} = {_as_toml(value)!r}: {reason}")
        self.key = key
        self.value = value
        self.reason = reason


def read_toml(
    name_or_path: str | Path, bundled_dir: Path, *, kind: str, error: type[Exception]
) -> tuple[dict[str, Any], Path]:
    """Parse a bundled file by name (``"x500_v2"``) or any ``.toml`` path.

    Every failure raises ``error`` with one line that starts with the path; a missing
    file lists the bundled ``kind`` files.
    """
    path = Path(name_or_path)
    if path.suffix != ".toml":
        path = bundled_dir / f"{name_or_path}.toml"
    try:
        return tomllib.loads(path.read_text(encoding="utf-8")), path
    except FileNotFoundError:
        bundled = ", ".join(sorted(p.stem for p in bundled_dir.glob("*.toml")))
        raise error(f"{path}: no such {kind} file (bundled: {bundled})") from None
    except (OSError, UnicodeDecodeError) as reason:
        raise error(f"{path}: cannot read ({reason})") from None
    except tomllib.TOMLDecodeError as reason:
        raise error(f"{path}: not valid TOML ({reason})") from None


def load(
    schema: type[T],
    name_or_path: str | Path,
    bundled_dir: Path,
    *,
    kind: str,
    error: type[Exception],
) -> T:
    """Read a bundled or user file and check it against ``schema``; one-line ``error``s."""
    document, path = read_toml(name_or_path, bundled_dir, kind=kind, error=error)
    return parse(schema, document, str(path), error)


def parse(schema: TypeForm[T], document: Any, source: str, error: type[Exception]) -> T:
    """Check a parsed document (or one built in code) against ``schema``: a table, or any
    type pydantic reads (a discriminated union such as a scenario fault).

    ``source`` starts the error's line: the file's path, or what the document stands for.
    """
    try:
        # mypy takes a type form for unhashable (python/mypy#11470, #20409); a class, a union
        # and an Annotated form are all hashable
        return _adapter(schema).validate_python(document)  # type: ignore[arg-type]
    except ValidationError as failure:
        raise error(f"{source}: {_describe(failure, document)}") from None


def json_schema(schema: type) -> dict[str, Any]:
    """The JSON Schema of a configuration file (TOML maps onto JSON one to one)."""
    return _adapter(schema).json_schema()


@functools.cache
def _adapter(schema: TypeForm[Any]) -> TypeAdapter[Any]:
    return TypeAdapter(schema)


def _describe(failure: ValidationError, document: Any) -> str:
    """The first problem as ``key 'a.b[2].c' = value: what was expected``."""
    problem = failure.errors(include_url=False)[0]
    kind, context = problem["type"], problem.get("ctx") or {}
    key, value, found = _locate(document, problem["loc"], missing=kind == "missing")
    reason = problem["msg"].removeprefix("Value error, ")
    cause = context.get("error")
    if isinstance(cause, FieldError):
        key = f"{key}.{cause.key}" if key else cause.key
        value, found, reason = cause.value, True, cause.reason
    elif kind in _BOUNDS:
        bound, symbol = _BOUNDS[kind]
        reason = f"expected a value {symbol} {context[bound]:g}"
    elif kind in ("too_short", "string_too_short"):
        reason = f"expected at least {context['min_length']} item(s)"
    elif kind in ("too_long", "string_too_long"):
        reason = f"expected at most {context['max_length']} item(s)"
    elif kind in ("union_tag_invalid", "union_tag_not_found"):  # the table-choosing key
        tag = context["discriminator"].strip("'")
        key = f"{key}.{tag}" if key else tag
        if kind == "union_tag_not_found":
            return f"key {key!r} is missing"
        value, reason = context["tag"], f"expected one of {context['expected_tags']}"
    elif reason.startswith("Input should be "):
        reason = "expected " + reason.removeprefix("Input should be ")
    elif reason:
        reason = reason[0].lower() + reason[1:]
    if kind == "missing":
        return f"key {key!r} is missing"
    if kind in ("unexpected_keyword_argument", "extra_forbidden"):
        return f"key {key!r} = {_as_toml(value)!r}: unknown key"
    if not key:
        return reason
    return f"key {key!r} = {_as_toml(value)!r}: {reason}" if found else f"key {key!r}: {reason}"


def _locate(document: Any, loc: tuple[int | str, ...], *, missing: bool) -> tuple[str, Any, bool]:
    """Follow pydantic's error location through the document: the dotted key as the file
    spells it, the value found there, and whether one was. A part the document lacks is a
    union's tag, which pydantic adds and the file does not have, unless it is the missing
    key itself (or a missing array item)."""
    key, node, found = "", document, True
    for index, part in enumerate(loc):
        if isinstance(node, Mapping) and part in node:
            key, node = f"{key}.{part}" if key else str(part), node[part]
        elif isinstance(node, list | tuple) and isinstance(part, int) and part < len(node):
            key, node = f"{key}[{part}]", node[part]
        elif isinstance(part, int):
            key, found = f"{key}[{part}]", False
        elif missing and index == len(loc) - 1:
            key, found = f"{key}.{part}" if key else part, False
    return key, node, found


#: pydantic's bound errors: the context key of the bound and how the message states it.
_BOUNDS = {
    "greater_than": ("gt", ">"),
    "greater_than_equal": ("ge", ">="),
    "less_than": ("lt", "<"),
    "less_than_equal": ("le", "<="),
}


def _as_toml(value: Any) -> Any:
    """A value as the file writes it: arrays as lists, enums as their strings."""
    if isinstance(value, tuple | list):
        return [_as_toml(item) for item in value]
    if isinstance(value, Enum):
        return value.value
    return value
