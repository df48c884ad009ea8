"""Text for a terminal: docstring markup removed, tables fitted to a width.

Docstrings are written in reStructuredText for the documentation site; the
command line shows their first sentences, so ``plain`` drops the markup
(````x````, ``:func:`~a.b.c```) that would otherwise print verbatim.
"""

from __future__ import annotations

import re
import textwrap
from collections.abc import Sequence

__all__ = ["WIDTH", "plain", "shorten", "table"]

#: Widest line the command line prints (details go behind ``--verbose``).
WIDTH = 100

_ROLE = re.compile(r":[\w:]+:`~?([^`<]*?)(?:\s*<[^>]*>)?`")
_LITERAL = re.compile(r"``(.+?)``")
_INTERPRETED = re.compile(r"(?<![\w`])`([^`]+)`(?![\w`])")


def plain(text: str) -> str:
    """``text`` without reStructuredText markup: roles keep their last name, literals
    and interpreted text lose their backquotes, whitespace runs become one space."""
    text = _ROLE.sub(lambda m: m.group(1).rsplit(".", 1)[-1] if "~" in m.group(0)
                     else m.group(1), text)
    text = _LITERAL.sub(r"\1", text)
    text = _INTERPRETED.sub(r"\1", text)
    return " ".join(text.split())


def shorten(text: str, width: int) -> str:
    """``text`` cut to ``width`` characters, ending in "…" when cut."""
    if len(text) <= width:
        return text
    return text[: max(width - 1, 0)].rstrip() + "…"


def table(head: Sequence[str], rows: Sequence[Sequence[str]], *,
          width: int | None = WIDTH) -> str:
    """Left-aligned columns under ``head``; the last column is wrapped under itself to
    fit ``width`` (``None``: one line per row)."""
    rows = [tuple(map(str, r)) for r in rows]
    w = [max(len(r[i]) for r in [*rows, tuple(head)]) for i in range(len(head) - 1)]
    indent = sum(w) + 2 * len(w)
    room = None if width is None else max(width - indent, 20)
    fmt = "  ".join(f"{{:<{n}}}" for n in w) + "  {}"

    def line(r: Sequence[str]) -> str:
        parts = [r[-1]] if room is None else (textwrap.wrap(r[-1], room) or [""])
        return "\n".join([fmt.format(*r[:-1], parts[0]).rstrip()]
                         + [" " * indent + p for p in parts[1:]])

    body = [line(tuple(head)), *(line(r) for r in rows)]
    rule = "-" * max(len(x) for b in body for x in b.split("\n"))
    return "\n".join([body[0], rule, *body[1:]])
