"""Moved to :mod:`pilworld.data.pairs` (a run's paired episodes and verdicts are data every layer reads)."""

from pilworld.data.pairs import Pair as Pair
from pilworld.data.pairs import PairedEpisodes as PairedEpisodes
from pilworld.data.pairs import load_pairs as load_pairs
