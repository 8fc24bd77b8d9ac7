"""A 32×32 copy of the simulated rig: world model v2 composites its geometry at test-friendly sizes."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.config.rig import RigConfig

ROOT = Path(__file__).resolve().parents[4]
SIM_RIG = ROOT / "configs" / "rig" / "sim_dual_ur5e.yaml"
SIZE = 32


@pytest.fixture(scope="session")
def rig32() -> RigConfig:
    rig = RigConfig.load(SIM_RIG)
    return RigConfig.model_validate({**rig.model_dump(), "image_size": {"width": SIZE, "height": SIZE}})
