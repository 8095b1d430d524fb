"""A griffe extension: the docstrings' reStructuredText roles read as Markdown code.

The docstrings are written for Sphinx-style readers (``:func:`table` ``, double-backtick
literals). Markdown already renders a double-backtick literal as code; a role would show
its ``:func:`` prefix, so each role becomes plain code before mkdocstrings renders it.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

#: ``:func:`~a.b` `` and its kin; ``~`` and a leading ``.`` only steer Sphinx's lookup.
ROLE = re.compile(r":(?:py:)?(?:func|class|data|mod|meth|attr|exc|obj|const):`[~.]?([^`]+)`")


def markdown_roles(text: str) -> str:
    """``text`` with every role replaced by its target as inline code."""
    return ROLE.sub(lambda match: f"`{match.group(1)}`", text)


class RstRoles(griffe.Extension):
    """Rewrites the roles of every docstring as it is loaded."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = markdown_roles(obj.docstring.value)
