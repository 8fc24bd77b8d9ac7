"""The live status block: redrawn in place on a terminal, one line per kept item in a log."""

from __future__ import annotations

import io

from pilworld.cli.terminal import StatusBlock


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_log_gets_one_line_per_kept_item_and_the_full_block_at_the_end() -> None:
    out = io.StringIO()
    block = StatusBlock(out)
    block.show(["views 1", "map", "last frame: kept: adds coverage"])
    block.show(["views 1", "map", "last frame: skipped: near-duplicate of view 0"])
    block.show(["views 1", "map", "last frame: skipped: near-duplicate of view 0"])
    block.show(["views 2", "map", "last frame: kept: adds tilt"])
    block.finish(["views 2", "map", "done"])
    assert out.getvalue().splitlines() == [
        "views 1 | last frame: kept: adds coverage",
        "views 2 | last frame: kept: adds tilt",
        "views 2",
        "map",
        "done",
    ]


def test_terminal_block_is_redrawn_in_place() -> None:
    out = _Tty()
    block = StatusBlock(out)
    block.show(["a", "b"])
    block.show(["c", "d"])
    assert out.getvalue() == "a\nb\n\x1b[2F\x1b[Jc\nd\n"
