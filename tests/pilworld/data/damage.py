"""The three ways a stored file is damaged in the integrity tests."""

from __future__ import annotations

from pathlib import Path

HOWS = ("delete", "truncate", "corrupt")


def damage(path: Path, how: str) -> None:
    """Delete ``path``, cut it to half its size, or flip one byte in its middle (same size, other content)."""
    data = path.read_bytes()
    if how == "delete":
        path.unlink()
    elif how == "truncate":
        path.write_bytes(data[: len(data) // 2])
    elif how == "corrupt":
        flipped = bytearray(data)
        flipped[len(data) // 2] ^= 0xFF
        path.write_bytes(bytes(flipped))
    else:
        raise ValueError(f"how: expected one of {HOWS}, got {how!r}")
