"""Data-parallel training over CPU processes on one machine (torch.distributed, gloo backend).

A small network's training step does not speed up with more intra-op threads on a CPU (the
diffusion policy's cpu preset: 150 steps at batch 64 take 26.9 s on one thread and 26.3 s on two,
docs/archive/notes/history.md), but two processes that each take half of every batch run side by side on two
cores. Every process holds the same weights; after each backward pass one all-reduce sums the
gradients, each weighted by its share of the batch, so every process applies the gradient of the
mean loss over the whole batch, as a single process would.
"""

from __future__ import annotations

import datetime
import logging
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch
import torch.distributed as dist
import torch.multiprocessing as mp
from torch.multiprocessing.spawn import ProcessException
from torch import nn

from grits_lab import errors

__all__ = ["batch_share", "reduce_gradients", "run_processes"]


def batch_share(indices: np.ndarray, rank: int, world_size: int) -> tuple[np.ndarray, float]:
    """This process's slice of a batch and its weight (slice size / batch size).

    indices: (B,) window indices of one training step. Returns (B_r,) contiguous indices, about
    B / world_size of them, and B_r / B, the factor that makes the weighted losses sum to the batch mean.
    """
    part = np.array_split(indices, world_size)[rank]
    return part, len(part) / max(len(indices), 1)


def reduce_gradients(module: nn.Module, weighted_loss: torch.Tensor) -> float:
    """Sum every process's gradients (and weighted losses) with one all-reduce; returns the batch loss.

    Call after `weighted_loss.backward()`, where weighted_loss = mean loss over this process's
    slice x its `batch_share` weight. A parameter without a gradient contributes zeros, so every
    process sends a buffer of the same size.
    """
    params = list(module.parameters())
    for p in params:
        if p.grad is None:
            p.grad = torch.zeros_like(p)
    flat = torch.cat([p.grad.reshape(-1) for p in params] + [weighted_loss.detach().reshape(1).to(params[0].grad.dtype)])
    dist.all_reduce(flat)
    offset = 0
    for p in params:
        n = p.grad.numel()
        p.grad.copy_(flat[offset : offset + n].view_as(p.grad))
        offset += n
    return float(flat[-1])


def _entry(rank: int, world_size: int, token: str, errors_queue: Any, fn: Callable[..., Any], args: Sequence[Any]) -> None:
    dist.init_process_group("gloo", init_method=Path(f"{token}.group").as_uri(), rank=rank, world_size=world_size,
                            timeout=datetime.timedelta(minutes=30))
    try:
        value = fn(rank, world_size, *args)
        if rank == 0:
            torch.save(value, f"{token}.result")
    except errors.GritsError as exc:
        errors_queue.put((type(exc).__name__, str(exc)))
        raise
    finally:
        dist.destroy_process_group()


def run_processes(fn: Callable[..., Any], world_size: int, args: Sequence[Any], workdir: str | Path) -> Any:
    """Run fn(rank, world_size, *args) in `world_size` fresh processes joined in one gloo group.

    fn and args must pickle (processes start with `spawn`, not `fork`: the caller may hold Ray
    or OpenMP threads). Returns rank 0's return value. A GritsError raised in any process is
    raised here with its type and message; the other processes are stopped.
    """
    token = Path(workdir).resolve() / f".processes_{np.random.default_rng().integers(1 << 62)}"
    group_file, result_file = Path(f"{token}.group"), Path(f"{token}.result")
    errors_queue = mp.get_context("spawn").SimpleQueue()
    spawn_log = logging.getLogger("torch.multiprocessing.spawn")  # its "terminating process" line would follow the error
    level = spawn_log.level
    spawn_log.setLevel(logging.ERROR)
    try:
        mp.start_processes(_entry, args=(world_size, str(token), errors_queue, fn, tuple(args)), nprocs=world_size,
                           join=True, start_method="spawn")
        return torch.load(result_file, weights_only=True)  # rank 0's summary: plain data, and the folder may be shared
    except ProcessException:
        if not errors_queue.empty():
            name, message = errors_queue.get()
            raise getattr(errors, name, errors.GritsError)(message) from None
        raise
    finally:
        spawn_log.setLevel(level)
        group_file.unlink(missing_ok=True)
        result_file.unlink(missing_ok=True)
