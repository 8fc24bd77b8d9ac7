"""Policies by name: the simulated rig's scripted checkpoints, or an openpi server's ``ws://`` address."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from pilworld.config.rig import RigConfig
from pilworld.policies.base import Policy
from pilworld.types import ChunkSpec

if TYPE_CHECKING:
    from simrig.tasks import Task


def policy_names() -> list[str]:
    from pilworld.policies.scripted import CHECKPOINTS

    return [c.name for c in CHECKPOINTS]


def default_checkpoint() -> str:
    """The rig's best checkpoint (the scripted stand-in for a trained VLA's final checkpoint)."""
    from pilworld.policies.scripted import BEST_CHECKPOINT

    return BEST_CHECKPOINT


CONNECT_TIMEOUT_ENV = "PILWORLD_POLICY_CONNECT_TIMEOUT"
REPLY_TIMEOUT_ENV = "PILWORLD_POLICY_REPLY_TIMEOUT"
DEFAULT_CONNECT_TIMEOUT_S = 10.0
DEFAULT_REPLY_TIMEOUT_S = 30.0


def policy_timeouts() -> tuple[float, float]:
    """Seconds an openpi server gets to connect (handshake and metadata) and to answer one request.

    From ``PILWORLD_POLICY_CONNECT_TIMEOUT`` / ``PILWORLD_POLICY_REPLY_TIMEOUT`` when set (a slow model
    on a shared GPU needs longer; tests need shorter), else 10 s and 30 s.
    """
    out = []
    for env, default in (
        (CONNECT_TIMEOUT_ENV, DEFAULT_CONNECT_TIMEOUT_S),
        (REPLY_TIMEOUT_ENV, DEFAULT_REPLY_TIMEOUT_S),
    ):
        raw = os.environ.get(env, "").strip()
        if not raw:
            out.append(default)
            continue
        try:
            value = float(raw)
        except ValueError:
            value = float("nan")
        if not value > 0 or value == float("inf"):
            raise ValueError(f"{env}: expected a positive number of seconds, got {raw!r}")
        out.append(value)
    return out[0], out[1]


def make_policy(
    name: str, rig: RigConfig, spec: ChunkSpec | None = None, task: Task | str | Path | None = None
) -> Policy:
    """``ws://host:port`` → an openpi websocket client; a scripted checkpoint name → that checkpoint.

    ``task`` (a loaded task, a packaged name or a task file) is the task a scripted checkpoint acts on,
    whatever the instruction's wording; without it (or for a hardware-only task, which it cannot act on)
    it recognises a packaged task by its instruction. A policy server ignores it."""
    spec = spec or ChunkSpec()
    if name.startswith(("ws://", "wss://")):
        from pilworld.policies.openpi.client import OpenPiClient

        connect_s, reply_s = policy_timeouts()
        # Any horizon >= K·Δ works; checked at the client, so a short chunk is the policy's error, not the loop's.
        return OpenPiClient(
            name, connect_timeout=connect_s, reply_timeout=reply_s, min_horizon=spec.executed_steps, name=name
        )
    from pilworld.policies.scripted import ScriptedPolicy

    if name not in policy_names():
        raise ValueError(
            f"checkpoint {name!r}: not a scripted checkpoint ({', '.join(policy_names())}) nor an openpi server "
            "address (ws://host:port)"
        )
    if task is not None:
        from simrig.tasks import load_task

        task = load_task(task)
        if not task.simulated:
            task = None
    return ScriptedPolicy(rig, name, horizon=spec.horizon, task=task)
