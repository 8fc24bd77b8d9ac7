"""Loading user-supplied arrays safely (never unpickle what a user did not create)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray


def load_npy(path: str | Path, *, what: str) -> NDArray[np.float64]:
    """Load a numeric ``.npy`` file with ``allow_pickle=False``; errors name ``what`` and the path."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what}: file not found: {path}")
    if path.suffix.lower() != ".npy":
        raise ValueError(f"{what}: expected a .npy file, got {path}")
    if path.stat().st_size == 0:
        raise ValueError(f"{what}: {path} is empty (0 bytes); expected a .npy array")
    try:
        arr: NDArray[np.float64] = np.load(path, allow_pickle=False)
    except (ValueError, EOFError, OSError) as err:  # cut short, not .npy, or a pickle
        detail = " ".join(str(err).split()) or "cut short"
        raise ValueError(f"{what}: {path} is not a plain numeric .npy array ({detail})") from None
    if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
        raise ValueError(f"{what}: {path} holds dtype {arr.dtype}; expected real numbers")
    if not np.all(np.isfinite(arr)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ValueError(f"{what}: {path} has a non-finite value {arr[bad].item()!r} at index {bad}")
    return arr.astype(np.float64)
