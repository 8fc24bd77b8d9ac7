"""Policies by name: the simulated rig's scripted checkpoints, or an openpi server's ``ws://`` address."""

from __future__ import annotations

from pilworld.config.rig import RigConfig
from pilworld.policies.base import Policy
from pilworld.types import ChunkSpec


def policy_names() -> list[str]:
    from pilworld.policies.scripted import CHECKPOINTS

    return [c.name for c in CHECKPOINTS]


def default_checkpoint() -> str:
    """The rig's best checkpoint (the scripted stand-in for a trained VLA's final checkpoint)."""
    from pilworld.policies.scripted import BEST_CHECKPOINT

    return BEST_CHECKPOINT


def make_policy(name: str, rig: RigConfig, spec: ChunkSpec | None = None) -> Policy:
    """``ws://host:port`` → an openpi websocket client; a scripted checkpoint name → that checkpoint."""
    spec = spec or ChunkSpec()
    if name.startswith(("ws://", "wss://")):
        from pilworld.policies.openpi.client import OpenPiClient

        return OpenPiClient(name)  # any horizon >= K·Δ works; the closed loop checks it per chunk
    from pilworld.policies.scripted import ScriptedPolicy

    if name not in policy_names():
        raise ValueError(
            f"checkpoint {name!r}: not a scripted checkpoint ({', '.join(policy_names())}) nor an openpi server "
            "address (ws://host:port)"
        )
    return ScriptedPolicy(rig, name, horizon=spec.horizon)
