"""Subtask starts (start observation + history) stored on their own: see :mod:`pilworld.starts.store`."""

from pilworld.starts.sources import StartsSource, load_starts
from pilworld.starts.store import StartsError, StartsWriter, StoredStart, start_id

__all__ = ["StartsError", "StartsSource", "StartsWriter", "StoredStart", "load_starts", "start_id"]
