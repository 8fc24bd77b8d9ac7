"""The one printer of ``pilworld bench``: summary lines, aligned tables, and the JSON result last.

Every bench prints the same way — human-readable lines (some of them a table), then, with ``--json``, the
whole result as one JSON object on the last line of stdout (scripts and tests read that line). Tables are
described by their columns instead of hand-aligned f-strings, so a header and its rows cannot drift apart.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any


def pct(x: Any) -> str:
    """A rate in [0, 1] as percent with one decimal; ``—`` when undefined."""
    return "—" if x is None else f"{100 * float(x):.1f}"


def num(x: Any, digits: int = 2) -> str:
    """A number with ``digits`` decimals; ``—`` when undefined."""
    return "—" if x is None else f"{float(x):.{digits}f}"


@dataclass(frozen=True)
class Column:
    """One table column: its title, width and alignment, and how a row's value becomes text.

    ``key`` picks the value from a row (a mapping key, or a callable on the row); ``fmt`` renders it
    (``str`` by default); ``sep`` goes before the cell (the gap to the previous column).
    """

    title: str
    width: int
    key: str | Callable[[Mapping[str, Any]], Any]
    fmt: Callable[[Any], str] = str
    align: str = ">"
    sep: str = ""

    def cell(self, text: str) -> str:
        return f"{self.sep}{text:{self.align}{self.width}}"

    def value(self, row: Mapping[str, Any]) -> str:
        raw = self.key(row) if callable(self.key) else row.get(self.key)
        return self.cell(self.fmt(raw))


def table(columns: Sequence[Column], rows: Iterable[Mapping[str, Any]], indent: str = "  ") -> list[str]:
    """The header line and one line per row, every cell aligned to its column."""
    lines = [indent + "".join(c.cell(c.title) for c in columns).rstrip()]
    lines += [indent + "".join(c.value(row) for c in columns).rstrip() for row in rows]
    return lines


def emit(args: argparse.Namespace, result: Mapping[str, Any], lines: Iterable[str] = ()) -> int:
    """Print ``lines``, then with ``--json`` the whole ``result`` as the last line; the command's exit status 0."""
    for line in lines:
        print(line)
    if getattr(args, "json", False):
        print(json.dumps(result))
    return 0
