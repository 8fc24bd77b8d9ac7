"""Observation-only scripted policies for the simulated rig: the stand-in for VLA checkpoints."""

from pilworld.policies.scripted.policy import ScriptedPolicy
from pilworld.policies.scripted.skill import BEST_CHECKPOINT, CHECKPOINTS, Checkpoint, checkpoint

__all__ = ["BEST_CHECKPOINT", "CHECKPOINTS", "Checkpoint", "ScriptedPolicy", "checkpoint"]
