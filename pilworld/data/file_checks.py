"""Cheap structural checks of stored files, for datasets (or files) that have no manifest to compare with.

An mp4 is a sequence of boxes, each starting with its size: walking the top-level boxes shows a file
cut short (the last box runs past the end) or missing its index (no ``moov``) without decoding a frame.
A parquet file starts and ends with ``PAR1`` and keeps its row count in the footer.
"""

from __future__ import annotations

import struct
from pathlib import Path

import pyarrow.parquet as pq


def mp4_problem(path: Path) -> str | None:
    """Why ``path`` is not a complete mp4 (a one-line reason), or None when its box structure is whole."""
    size = path.stat().st_size
    seen: set[bytes] = set()
    with path.open("rb") as fh:
        pos = 0
        while pos < size:
            fh.seek(pos)
            head = fh.read(8)
            if len(head) < 8:
                return f"truncated: {size - pos} stray byte(s) after the last box"
            box_size, kind = struct.unpack(">I4s", head)
            if box_size == 1:  # 64-bit size follows
                big = fh.read(8)
                if len(big) < 8:
                    return "truncated inside a box header"
                box_size = struct.unpack(">Q", big)[0]
            elif box_size == 0:  # runs to the end of the file
                box_size = size - pos
            if box_size < 8:
                return f"corrupt box {kind.decode('latin-1')!r} at byte {pos} (size {box_size})"
            if pos + box_size > size:
                name = kind.decode("latin-1")
                return f"truncated: box {name!r} at byte {pos} needs {box_size} bytes, {size - pos} left"
            seen.add(kind)
            pos += box_size
    if b"moov" not in seen:
        return "no moov box (not a finished mp4)"
    return None


def parquet_problem(path: Path, rows: int | None = None) -> str | None:
    """Why ``path`` is not a readable parquet file (with ``rows``: of that many rows), or None."""
    try:
        meta = pq.ParquetFile(path).metadata
    except Exception as err:  # pyarrow raises several types for a damaged footer
        return f"unreadable parquet ({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})"
    if rows is not None and meta.num_rows != rows:
        return f"holds {meta.num_rows} rows, expected {rows}"
    return None
