"""``torchrun`` support: the process group from the environment torchrun sets (DDP; gloo on CPU, nccl on GPUs).

Run ``torchrun --nproc_per_node N -m pilworld train …`` (or ``pilworld train … --nproc N``, which
starts torchrun for you). Every rank computes its slice of each global batch (see
:meth:`TrainData.clip_indices`) and ``DistributedDataParallel`` averages the gradients, so the ranks
stay bit-identical; only rank 0 writes checkpoints and logs.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.distributed as dist


@dataclass(frozen=True)
class Dist:
    rank: int = 0
    world: int = 1
    local_rank: int = 0

    @property
    def enabled(self) -> bool:
        return self.world > 1

    @property
    def main(self) -> bool:
        return self.rank == 0

    def barrier(self) -> None:
        if self.enabled:
            dist.barrier()

    def device(self) -> torch.device:
        if torch.cuda.is_available() and self.enabled:
            return torch.device("cuda", self.local_rank)
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def init_distributed() -> Dist:
    """Join the process group when launched by torchrun (``WORLD_SIZE`` > 1), else a single process."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return Dist()
    rank, local = int(os.environ["RANK"]), int(os.environ.get("LOCAL_RANK", "0"))
    if not dist.is_initialized():
        backend = "nccl" if torch.cuda.is_available() else "gloo"
        if backend == "nccl":
            torch.cuda.set_device(local)
        dist.init_process_group(backend=backend)
    return Dist(rank, world, local)


def shutdown(d: Dist) -> None:
    if d.enabled and dist.is_initialized():
        dist.destroy_process_group()
