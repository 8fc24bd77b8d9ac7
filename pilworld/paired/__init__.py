"""The paired runner: each subtask once on the robot and once in the world model, from the same start."""

from pilworld.paired.episodes import rollout_episode
from pilworld.paired.runner import PairedConfig, PairedSubtask, paired_run, plan_subtasks

__all__ = ["PairedConfig", "PairedSubtask", "paired_run", "plan_subtasks", "rollout_episode"]
