"""The command-line reference, read from the argparse parsers themselves.

Each console script of ``[project.scripts]`` names its ``main``; the module beside it has
:data:`PARSER_FUNCTION`, which builds the parser ``main`` runs. The reference therefore
says what ``--help`` says, subcommand by subcommand, and cannot fall behind it.
"""

from __future__ import annotations

import argparse
import importlib

from docsgen import prose, pyproject, table_cell

#: Each CLI module's function that builds its parser without running it.
PARSER_FUNCTION = "build_parser"


def parsers() -> dict[str, argparse.ArgumentParser]:
    """Each console script's parser, by the script's name."""
    found = {}
    for script, target in pyproject()["project"]["scripts"].items():
        module = importlib.import_module(target.partition(":")[0])
        found[script] = getattr(module, PARSER_FUNCTION)()
    return found


def render_cli(parsers: dict[str, argparse.ArgumentParser]) -> str:
    """One page: every command, its subcommands and each argument."""
    lines = [
        "# Command line",
        "",
        "Generated from the commands' own argparse parsers: what `--help` prints, as tables.",
        "",
    ]
    for name, parser in parsers.items():
        lines += _command(name, parser, level=2)
    return "\n".join(lines) + "\n"


def _command(name: str, parser: argparse.ArgumentParser, level: int) -> list[str]:
    lines = [f"{'#' * level} `{name}`", ""]
    if parser.description:
        lines += [prose(parser.description), ""]
    usage = parser.format_usage().removeprefix("usage: ").strip()
    lines += ["```text", usage, "```", ""]
    rows = [_row(action) for action in parser._actions if not _hidden(action)]
    if rows:
        lines += ["| argument | help | choices | default |", "|---|---|---|---|", *rows, ""]
    if parser.epilog:
        lines += ["```text", parser.epilog, "```", ""]
    for sub_name, sub_parser in _subcommands(parser):
        lines += _command(f"{name} {sub_name}", sub_parser, level + 1)
    return lines


def _hidden(action: argparse.Action) -> bool:
    return isinstance(action, argparse._HelpAction | argparse._SubParsersAction) or (
        action.help == argparse.SUPPRESS
    )


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return list(action.choices.items())
    return []


def _row(action: argparse.Action) -> str:
    if action.option_strings:
        spelled = ", ".join(action.option_strings)
        if action.nargs != 0:
            spelled += " " + _metavar(action)
    else:
        spelled = _metavar(action)
    choices = ", ".join(f"`{c}`" for c in action.choices) if action.choices else ""
    return (
        f"| `{table_cell(spelled)}` | {prose(table_cell(action.help or ''))} | {choices} "
        f"| {_default(action)} |"
    )


def _metavar(action: argparse.Action) -> str:
    if isinstance(action.metavar, tuple):
        return " ".join(action.metavar)
    if action.metavar is not None:
        return action.metavar
    if action.option_strings:
        return action.dest.upper()
    return action.dest


def _default(action: argparse.Action) -> str:
    """The default as a user meets it: nothing for a flag off or an option left unset."""
    if action.required or action.default in (None, argparse.SUPPRESS, False, []):
        return ""
    return f"`{table_cell(action.default)}`"
