"""Fixtures of the training tests: the synthetic dataset (once per session) and a private clip cache."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from .synthetic_data import write_dataset


@pytest.fixture(scope="session")
def clip_cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """Decoded clip frames go to a temporary cache, not ``~/.cache/pilworld``."""
    cache = tmp_path_factory.mktemp("clip_cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PILWORLD_CACHE", str(cache))
        yield cache


@pytest.fixture(scope="session")
def dataset(tmp_path_factory: pytest.TempPathFactory, clip_cache: Path) -> Path:
    return write_dataset(tmp_path_factory.mktemp("wm_train") / "ds")
