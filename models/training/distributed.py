"""Multi-process training under ``torchrun``: DistributedDataParallel, gloo on CPU and nccl on GPU.

torchrun sets RANK, WORLD_SIZE and LOCAL_RANK (and the rendezvous address); without them training is one
process, exactly as before. Each rank draws its own batches of ``batch_size / world_size`` from its own
shard of the training samples with its own seed; DDP averages the gradients, which for the mean-squared
error over equal shards is the gradient of one global batch. Rank 0 alone writes the run directory.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, replace

import torch
from torch import nn

from models.data.batches import TrainingSet
from protocol.errors import UserError

log = logging.getLogger(__name__)

#: rank r > 0 augments with seed + r * RANK_SEED_STRIDE (rank 0 keeps the single-process seed)
RANK_SEED_STRIDE = 1_000_003


class DistributedError(UserError):
    """A multi-process run that cannot be set up as asked (its message says what to change)."""


@dataclass(frozen=True)
class World:
    """This process's place among the training processes (rank 0 of 1 without torchrun)."""

    rank: int = 0
    size: int = 1
    local_rank: int = 0

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    @property
    def distributed(self) -> bool:
        return self.size > 1


SINGLE = World()  # one process, no torchrun


def world_from_env() -> World:
    """The world torchrun describes in the environment."""
    env = os.environ
    return World(int(env.get("RANK", 0)), int(env.get("WORLD_SIZE", 1)), int(env.get("LOCAL_RANK", 0)))


def init_world(world: World) -> None:
    """Join the process group (once); nccl when this rank has a GPU, else gloo."""
    import torch.distributed as dist

    if not world.distributed or dist.is_initialized():
        return
    backend = "nccl" if torch.cuda.is_available() else "gloo"
    if backend == "nccl":
        torch.cuda.set_device(world.local_rank)
    dist.init_process_group(backend=backend)
    log.info("rank %d of %d joined (%s)", world.rank, world.size, backend)
    if not world.is_main:  # one voice: rank 0 logs the run, the others only their warnings and errors
        logging.getLogger().setLevel(logging.WARNING)


def close_world(world: World) -> None:
    import torch.distributed as dist

    if world.distributed and dist.is_initialized():
        dist.destroy_process_group()


def wrap(model: nn.Module, world: World) -> nn.Module:
    """The module to train: DDP around ``model`` (which keeps the same parameters) when distributed."""
    if not world.distributed:
        return model
    from torch.nn.parallel import DistributedDataParallel

    return DistributedDataParallel(model)


def shard(data: TrainingSet, world: World) -> TrainingSet:
    """This rank's samples (every size-th, from its rank) and its share of the global batch."""
    if not world.distributed:
        return data
    if data.batch_size % world.size:
        raise DistributedError(f"batch size {data.batch_size} does not split over {world.size} processes: "
                               "give a recipe [training] batch_size divisible by --nproc_per_node")
    take = slice(world.rank, None, world.size)
    return replace(data, indices=data.indices[take], steering=data.steering[take], has_sides=data.has_sides[take],
                   batch_size=data.batch_size // world.size,
                   groups=None if data.groups is None else data.groups[take],
                   middles=None if data.middles is None else data.middles[take])


def rank_seed(seed: int, world: World) -> int:
    return seed + world.rank * RANK_SEED_STRIDE


def agree(flag: bool, world: World) -> bool:
    """True on every rank once any rank's flag is (a Ctrl-C stops all ranks at the same step)."""
    if not world.distributed:
        return flag
    import torch.distributed as dist

    t = torch.tensor([int(flag)], device="cuda" if dist.get_backend() == "nccl" else "cpu")
    dist.all_reduce(t, op=dist.ReduceOp.MAX)
    return bool(t.item())


def train_step(model: nn.Module, optimizer: torch.optim.Optimizer, loss_fn: nn.Module, x: torch.Tensor,
               y: torch.Tensor) -> float:
    """One optimizer step on one (local) batch; under DDP the backward pass averages the gradients."""
    optimizer.zero_grad(set_to_none=True)
    loss = loss_fn(model(x), y)
    loss.backward()
    optimizer.step()
    return loss.item()
