"""A minimal one-page vector PDF of black rectangles, written by hand so that the page is exactly to scale.

Plotting libraries add padding, snap to their own DPI or rasterise; a calibration target must print at its
true size, so the page here is the board's physical size (``MediaBox`` in points, 1 pt = 1/72 inch) and
every square and marker cell is an exact vector rectangle. Only PDF 1.4 basics are used: one content
stream with ``re``/``f`` fills and, optionally, one line of text in the standard Helvetica font (one of the
14 fonts every reader has, so nothing is embedded).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Final

__all__ = ["POINTS_PER_METRE", "page_size_points", "write_rectangles_pdf"]

POINTS_PER_METRE: Final = 72.0 / 0.0254


def _num(value: float) -> str:
    # 1e-4 pt = 35 nm: far below printer resolution, and short enough to keep the file small.
    text = f"{value:.4f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _pdf_string(text: str) -> str:
    ascii_text = text.encode("latin-1", errors="replace").decode("latin-1")
    return "(" + ascii_text.replace("\\", "\\\\").replace("(", "\\(").replace(")", "\\)") + ")"


def page_size_points(page_size_m: tuple[float, float]) -> tuple[float, float]:
    """Page width and height in PDF points for a page of ``page_size_m`` metres."""
    return page_size_m[0] * POINTS_PER_METRE, page_size_m[1] * POINTS_PER_METRE


def write_rectangles_pdf(
    path: str | Path,
    page_size_m: tuple[float, float],
    rects_m: Sequence[tuple[float, float, float, float]],
    caption: str | None = None,
    caption_at_m: tuple[float, float] = (0.0, 0.0),
    caption_pt: float = 7.0,
    title: str = "",
) -> tuple[float, float]:
    """Write ``rects_m`` (``x0, y0, x1, y1`` in metres, origin top-left, y down) filled black on a white page.

    ``caption`` is drawn with its baseline starting at ``caption_at_m`` (same frame) in a mid grey, so it
    cannot be mistaken for part of the pattern. Returns the page size in points.
    """
    w_m, h_m = page_size_m
    if not (math.isfinite(w_m) and math.isfinite(h_m) and w_m > 0.0 and h_m > 0.0):
        raise ValueError(f"page_size_m must be two positive lengths in metres, got {page_size_m!r}")
    w_pt, h_pt = page_size_points(page_size_m)
    ops = ["0 g"]
    for x0, y0, x1, y1 in rects_m:
        # PDF user space has y up from the bottom-left corner.
        ops.append(
            f"{_num(x0 * POINTS_PER_METRE)} {_num(h_pt - y1 * POINTS_PER_METRE)} "
            f"{_num((x1 - x0) * POINTS_PER_METRE)} {_num((y1 - y0) * POINTS_PER_METRE)} re"
        )
    ops.append("f")
    resources = "<< >>"
    if caption:
        x, y = caption_at_m
        ops.append(
            f"BT 0.45 g /F1 {_num(caption_pt)} Tf {_num(x * POINTS_PER_METRE)} "
            f"{_num(h_pt - y * POINTS_PER_METRE)} Td {_pdf_string(caption)} Tj ET"
        )
        resources = "<< /Font << /F1 << /Type /Font /Subtype /Type1 /BaseFont /Helvetica >> >> >>"
    content = ("\n".join(ops) + "\n").encode("ascii")
    objects = [
        b"<< /Type /Catalog /Pages 2 0 R >>",
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
        (
            f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {_num(w_pt)} {_num(h_pt)}] "
            f"/Resources {resources} /Contents 4 0 R >>"
        ).encode("ascii"),
        f"<< /Length {len(content)} >>\nstream\n".encode("ascii") + content + b"endstream",
        f"<< /Title {_pdf_string(title)} /Producer (pilworld calib) >>".encode("latin-1"),
    ]
    out = bytearray(b"%PDF-1.4\n%\xe2\xe3\xcf\xd3\n")  # the binary comment marks the file as binary
    offsets = []
    for number, body in enumerate(objects, start=1):
        offsets.append(len(out))
        out += f"{number} 0 obj\n".encode("ascii") + body + b"\nendobj\n"
    xref = len(out)
    out += f"xref\n0 {len(objects) + 1}\n0000000000 65535 f \n".encode("ascii")
    for offset in offsets:
        out += f"{offset:010d} 00000 n \n".encode("ascii")
    out += (
        f"trailer\n<< /Size {len(objects) + 1} /Root 1 0 R /Info {len(objects)} 0 R >>\nstartxref\n{xref}\n%%EOF\n"
    ).encode("ascii")
    Path(path).write_bytes(bytes(out))
    return w_pt, h_pt
