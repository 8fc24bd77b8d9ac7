"""bench chunk-latency: model lists are parsed with clear errors, and every model gets timed rounds."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from pilworld.bench.chunk_latency import parse_models, run_chunk_latency
from pilworld.world_model import V1_CHECKPOINT
from pilworld.world_model.composite.checkpoint import save_composite
from pilworld.world_model.composite.model import CompositeConfig, CompositeWorldModel

ROOT = Path(__file__).resolve().parents[3]
RIG = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"


def test_parse_models(tmp_path: Path) -> None:
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "config.json").write_text("{}")
    assert parse_models(f"a={tmp_path / 'm'}") == {"a": str(tmp_path / "m")}
    assert parse_models(str(tmp_path / "m")) == {"m": str(tmp_path / "m")}
    with pytest.raises(ValueError, match="not a world-model folder"):
        parse_models(f"a={tmp_path / 'nothing'}")
    with pytest.raises(ValueError, match="twice"):
        parse_models(f"a={tmp_path / 'm'},a={tmp_path / 'm'}")
    with pytest.raises(ValueError, match="at least one"):
        parse_models(" , ")


def test_both_models_are_timed(tmp_path: Path) -> None:
    torch.manual_seed(0)
    v2 = save_composite(CompositeWorldModel(CompositeConfig()), tmp_path / "v2")
    out = run_chunk_latency({"v1": str(V1_CHECKPOINT), "v2": str(v2)}, rig=RIG, repeats=2, warmup=1)
    assert set(out["models"]) == {"v1", "v2"}
    assert out["models"]["v1"]["ratio_to_first"] == 1.0
    assert all(m["median_ms"] > 0 for m in out["models"].values())
