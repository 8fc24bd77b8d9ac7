"""Moved to :mod:`pilworld.io.atomic` (files are written whole or not at all, for every package)."""

from pilworld.io.atomic import atomic_write as atomic_write
from pilworld.io.atomic import write_json as write_json
