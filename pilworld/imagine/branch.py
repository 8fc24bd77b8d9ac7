"""Moved to :mod:`pilworld.paired.imagined_branch` (a paired run's imagined branch; imagined-only runs reuse it)."""

from pilworld.paired.imagined_branch import branch_episode as branch_episode
from pilworld.paired.imagined_branch import inference_threads as inference_threads
from pilworld.paired.imagined_branch import run_imagined as run_imagined
from pilworld.paired.imagined_branch import torch_threads as torch_threads
