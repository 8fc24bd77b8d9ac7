"""Importers behind ``pilworld data convert``: LeRobot v2.1 / v3.0 and ALOHA HDF5 → our episode store.

Each importer (:mod:`.lerobot_v21`, :mod:`.lerobot_v30`, :mod:`.aloha_hdf5`) reads one episode at a
time through an optional :class:`ConvertMapping` (camera selection and renaming, state/action keys,
resize, default instruction); :func:`convert` detects the format, writes with
:class:`~pilworld.data.writer.EpisodeWriter` and resumes an interrupted conversion.
"""

from pilworld.data.convert.base import EpisodeSource
from pilworld.data.convert.mapping import ConvertMapping, default_view_name, load_mapping
from pilworld.data.convert.run import FORMATS, convert, detect_format, open_source

__all__ = [
    "FORMATS",
    "ConvertMapping",
    "EpisodeSource",
    "convert",
    "default_view_name",
    "detect_format",
    "load_mapping",
    "open_source",
]
