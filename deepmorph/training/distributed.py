"""Where training runs: the device, and the processes of a data-parallel run (torchrun).

One drawing trains on N processes when launched by ``torchrun --nproc_per_node N -m deepmorph
train ...``: each process (a *rank*) reads its place from the environment torchrun sets
(``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK``, ``MASTER_ADDR``, ``MASTER_PORT``) and joins one
``torch.distributed`` process group (NCCL on GPUs, gloo on CPUs).

The global batch is drawn from ``shards`` random streams, shard ``i`` from its own generator
seeded by :func:`shard_seed`; rank ``r`` of ``W`` draws shards ``r, r + W, ...``, accumulates
their gradients (each weighted by its share of the batch) and the gradients are summed across
ranks by one all-reduce, the all-reduce that ``DistributedDataParallel`` makes. So a run's
numbers depend on its seed and its shards, not on how many processes share the shards: one
process with ``shards=2`` and two processes train the same model, and a checkpoint resumes on
any number of processes up to its shards. (The reduction is written out here rather than by
wrapping the networks in ``DistributedDataParallel`` because a step accumulates several shards
per rank, batch-norm statistics are averaged over shards, and the decoder's readout starts
training mid-run, which a ``DistributedDataParallel`` wrapper fixes at construction.)
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import torch
import torch.distributed as dist
from torch import Tensor, nn

from deepmorph_core.errors import DeepMorphError


@dataclass(frozen=True)
class World:
    """This process's place in a data-parallel run (one process: rank 0 of 1).

    Attributes:
        rank: this process's index among all processes.
        size: how many processes train together.
        local_rank: its index on this machine (which GPU it uses).
    """

    rank: int = 0
    size: int = 1
    local_rank: int = 0

    @property
    def main(self) -> bool:
        """Whether this process writes files and prints (rank 0)."""
        return self.rank == 0

    @property
    def distributed(self) -> bool:
        return self.size > 1


def world_from_env(env: dict[str, str] | None = None) -> World:
    """The :class:`World` torchrun describes in the environment (one process when it does not).

    Raises:
        DeepMorphError: values that are not numbers, or a rank outside the world.
    """
    env = dict(os.environ) if env is None else env
    try:
        rank, size, local = (int(env.get(k, d)) for k, d in (("RANK", "0"), ("WORLD_SIZE", "1"), ("LOCAL_RANK", "0")))
    except ValueError:
        raise DeepMorphError("RANK, WORLD_SIZE and LOCAL_RANK must be whole numbers (torchrun sets them)") from None
    if size < 1 or not 0 <= rank < size or local < 0:
        raise DeepMorphError(f"RANK {rank} and WORLD_SIZE {size} do not describe a process of the run")
    return World(rank, size, local)


def join(world: World, device: str) -> tuple[torch.device, bool]:
    """Join the run's process group (NCCL for ``cuda``, gloo for ``cpu``) when there is more than
    one process and none is joined yet.

    Returns:
        This process's torch device (``cuda:<local rank>`` on GPUs), and whether this call
        joined the group (then :func:`leave` it when done).
    """
    if device == "cuda":
        index = world.local_rank if world.distributed else torch.cuda.current_device()
        if index >= torch.cuda.device_count():
            raise DeepMorphError(
                f"LOCAL_RANK {world.local_rank}: this machine has {torch.cuda.device_count()} CUDA devices; start "
                "at most that many processes per node"
            )
        torch.cuda.set_device(index)
        target = torch.device("cuda", index)
    else:
        target = torch.device("cpu")
    joined = world.distributed and not dist.is_initialized()
    if joined:
        # torch._dynamo (imported by the optimisers on first use) keeps hold of a process group
        # that exists when it is first imported, so that group would outlive leave(): its gloo
        # threads then free their last collective's tensors while the interpreter exits, which
        # aborts the process (SIGABRT, "terminate called without an active exception") after
        # the work is done. Imported first, it holds none.
        importlib.import_module("torch._dynamo")

        dist.init_process_group("nccl" if device == "cuda" else "gloo", rank=world.rank, world_size=world.size)
    return target, joined


def leave() -> None:
    """Leave the process group, if this process joined one."""
    if dist.is_available() and dist.is_initialized():
        dist.destroy_process_group()


def shard_seed(seed: int, shard: int) -> int:
    """The seed of shard ``shard``'s random stream; shard 0's is the run's seed, so a run with
    one shard draws exactly what a run drew before shards existed."""
    return (seed + shard * 0x9E3779B97F4A7C15) % (1 << 63)


def shard_sizes(batch: int, shards: int) -> list[int]:
    """How many rows of a ``batch`` each shard draws (as even as can be, larger shards first)."""
    return [batch // shards + (i < batch % shards) for i in range(shards)]


def rank_shards(shards: int, world: World) -> list[int]:
    """The shards rank ``world.rank`` draws.

    Raises:
        DeepMorphError: more processes than shards (a process would have nothing to do).
    """
    if world.size > shards:
        raise DeepMorphError(
            f"{world.size} processes but the batch is drawn from {shards} random streams (--shards); "
            f"run at most {shards} processes, or start a new training with --shards {world.size}"
        )
    return list(range(world.rank, shards, world.size))


def all_reduce_sum(tensors: Iterable[Tensor], world: World) -> None:
    """Sum ``tensors`` (all on one device, of one float dtype) across the ranks, in place, with
    one flat all-reduce; nothing to do for one process."""
    tensors = list(tensors)
    if not world.distributed or not tensors:
        return
    flat = torch.cat([t.reshape(-1) for t in tensors])
    dist.all_reduce(flat)
    offset = 0
    for t in tensors:
        n = t.numel()
        t.copy_(flat[offset : offset + n].view_as(t))
        offset += n


def sum_gradients(params: Iterable[nn.Parameter], world: World) -> None:
    """Sum the gradients of ``params`` across the ranks (a parameter without a gradient on this
    rank counts as zero, so every rank takes part in the same reduction)."""
    if not world.distributed:
        return
    params = [p for p in params if p.requires_grad]
    for p in params:
        if p.grad is None:
            p.grad = torch.zeros_like(p)
    all_reduce_sum([p.grad for p in params], world)


def broadcast_module(module: nn.Module, world: World) -> None:
    """Give every rank rank 0's parameters and buffers of ``module``."""
    if not world.distributed:
        return
    with torch.no_grad():
        for t in [*module.parameters(), *module.buffers()]:
            dist.broadcast(t.data, 0)


def gather_objects(obj: Any, world: World) -> list[Any]:
    """Every rank's ``obj`` (picklable), in rank order, on every rank."""
    if not world.distributed:
        return [obj]
    out: list[Any] = [None] * world.size
    dist.all_gather_object(out, obj)
    return out


class BatchNormShards:
    """Batch-norm running statistics as the mean over a step's shards, whichever rank drew them.

    Each shard's forward pass starts from the step's statistics (:meth:`start`); its updated
    statistics are added up (:meth:`add`); :meth:`finish` sums them across ranks and sets the
    mean. With one shard this is exactly what the forward pass did.
    """

    def __init__(self, module: nn.Module) -> None:
        norms = [m for m in module.modules() if isinstance(m, nn.modules.batchnorm._BatchNorm)]
        self.stats = [t for m in norms for t in (m.running_mean, m.running_var) if t is not None]
        self.counts = [m.num_batches_tracked for m in norms if m.num_batches_tracked is not None]
        self.before = [t.clone() for t in self.stats]
        self.counts_before = [t.clone() for t in self.counts]
        self.sums = [torch.zeros_like(t) for t in self.stats]

    def start(self) -> None:
        """Before a shard's forward pass: the step's statistics."""
        with torch.no_grad():
            for t, b in zip(self.stats, self.before):
                t.copy_(b)

    def add(self) -> None:
        """After a shard's forward pass: add its statistics."""
        with torch.no_grad():
            for s, t in zip(self.sums, self.stats):
                s.add_(t)

    def finish(self, shards: int, world: World) -> None:
        """The mean over all ``shards`` of the step, on every rank; the batch counters advance by one."""
        all_reduce_sum(self.sums, world)
        with torch.no_grad():
            for t, s in zip(self.stats, self.sums):
                t.copy_(s / shards)
            for t, b in zip(self.counts, self.counts_before):
                t.copy_(b + 1)
