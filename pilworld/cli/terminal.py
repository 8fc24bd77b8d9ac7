"""A live status block on the terminal, and Enter as a stop key, for commands that wait on a person.

On a terminal the block is redrawn in place (ANSI: cursor up, clear to the end); in a log (no TTY) one line
per kept item is printed, so a CI log shows one line per event rather than a redraw every second.
"""

from __future__ import annotations

import select
import sys
from typing import TextIO


class StatusBlock:
    """Redraws a few lines in place on a TTY; otherwise prints one line per kept item (``keep_prefix``)."""

    def __init__(self, stream: TextIO | None = None, keep_prefix: str = "last frame: kept") -> None:
        self.stream = stream or sys.stdout
        self.keep_prefix = keep_prefix
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._drawn = 0
        self._last: list[str] = []

    def show(self, lines: list[str]) -> None:
        if self.tty:
            if self._drawn:
                self.stream.write(f"\x1b[{self._drawn}F\x1b[J")
            self.stream.write("\n".join(lines) + "\n")
            self._drawn = len(lines)
        else:
            # In a log: the counts and the latest decision when something was kept (``keep_prefix``), not every
            # skipped frame; the whole block (the map) only at the end.
            if lines[-1].startswith(self.keep_prefix) and lines != self._last:
                self.stream.write(f"{lines[0]} | {lines[-1]}\n")
            self._last = list(lines)
        self.stream.flush()

    def finish(self, lines: list[str]) -> None:
        """Print the final block in full (also in a log)."""
        if self.tty:
            self.show(lines)
        else:
            self.stream.write("\n".join(lines) + "\n")
            self.stream.flush()
        self._drawn = 0


def enter_pressed() -> bool:
    """Whether the operator pressed Enter (a line is waiting on a terminal's stdin); never blocks."""
    if not sys.stdin.isatty():
        return False
    ready, _, _ = select.select([sys.stdin], [], [], 0.0)
    if ready:
        sys.stdin.readline()
        return True
    return False
