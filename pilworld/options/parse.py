"""Option text turned into values: comma-separated lists and names (or ``all``), ``WIDTHxHEIGHT`` sizes.

A bad value is a one-line ``ValueError`` naming the flag (``pilworld`` exits 2 on it: :mod:`pilworld.cli.main`).
"""

from __future__ import annotations


def parse_list(value: str) -> list[str]:
    """The comma-separated items of ``value``, stripped, empty ones dropped (``""`` gives ``[]``)."""
    return [v.strip() for v in value.split(",") if v.strip()]


def parse_names(value: str, all_names: list[str], what: str) -> list[str]:
    """``value`` as a list of known names: ``all`` gives ``all_names``; an unknown or empty list is refused."""
    if value.strip() == "all":
        return all_names
    listed = parse_list(value)
    bad = [n for n in listed if n not in all_names]
    if bad or not listed:
        raise ValueError(f"{what}: unknown {bad or value!r}; choose from {', '.join(all_names)} or 'all'")
    return listed


def parse_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` (each 1..8192) as ``(width, height)``; the error names ``--size``."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"--size: expected WIDTHxHEIGHT such as 128x128, got {text!r}") from None
    if not (0 < w <= 8192 and 0 < h <= 8192):
        raise ValueError(f"--size: width and height must be in 1..8192, got {text!r}")
    return w, h
