"""Where the simulated rig's own files live: package data, so the CLI works outside a checkout.

``configs/rig/sim_dual_ur5e.yaml`` and ``configs/tasks/`` in a checkout are links to these, so the
paths the docs use keep working.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

PACKAGE_DIR: Final = Path(__file__).resolve().parent
SIM_RIG: Final = PACKAGE_DIR / "rig" / "sim_dual_ur5e.yaml"  # the simulated rig's config: every default names it
TASKS_DIR: Final = PACKAGE_DIR / "tasks" / "files"  # the packaged task files (and the meshes they use)
# How model and training settings spell the simulated rig: relative to a checkout's root (the link to SIM_RIG).
SIM_RIG_IN_CHECKOUT: Final = "configs/rig/sim_dual_ur5e.yaml"


def resolve_rig(path: str | Path, root: Path) -> Path:
    """``path`` as given if absolute, else relative to ``root`` (a checkout); the checkout spelling of the
    simulated rig falls back to :data:`SIM_RIG` where there is no checkout (an installed package)."""
    p = Path(path)
    if p.is_absolute():
        return p
    if not (root / p).exists() and p.as_posix() == SIM_RIG_IN_CHECKOUT:
        return SIM_RIG
    return root / p
