"""One training loop for the policies that learn from demonstration windows (diffusion policy, BC).

A run writes into `output_dir`: `checkpoints/last.pt` (and `step_<N>.pt` when `keep_every` is
set), `metrics.csv` (train loss, learning rate, validation loss, steps/s, rollout rates when
asked; readable with pandas), `tensorboard/` when TensorBoard is installed, and `config.yaml`.
Running the same config again resumes from `last.pt`: the model, EMA, optimizer, LR schedule,
step and noise generator continue, the LR schedule always spans the config's `max_steps`, and
batches are a function of (seed, step), so a stopped-and-resumed run ends with the same weights
as an uninterrupted one.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import torch
import yaml
from torch import nn
from tqdm import tqdm

from grits_lab.config import config_fingerprint, config_to_dict, require
from grits_lab.errors import ConfigError, StorageError
from grits_lab.io import ensure_writable_dir, exclusive_directory, write_text_atomic
from grits_lab.policies.control import RolloutSettings, RolloutsFactory, rollout_episodes
from grits_lab.policies.diffusion.demo_windows import DemoWindowDataset, dataset_fingerprint, list_demo_episodes, split_demo_episodes
from grits_lab.records import CPU_KERNELS
from grits_lab.training import (
    EMA, MetricLogger, load_checkpoint, require_finite_loss, resolve_device, save_checkpoint, set_torch_threads,
    warmup_cosine,
)
from grits_lab.training.metrics_log import TrackingConfig
from grits_lab.training.data_parallel import batch_share, reduce_gradients, run_processes
from grits_lab.versions import PROTOCOL, cpu_kernels


@dataclass
class DemoTrainConfig:
    """What every demonstration-trained policy's experiment sets; subclasses add `policy` and their own keys."""

    dataset: str
    output_dir: str
    seed: int = 0
    device: str = "auto"
    num_threads: int = 2  # torch intra-op threads on CPU (0 = torch default), per process
    num_processes: int = 1  # data-parallel CPU processes, each taking batch_size / num_processes of every batch
    splits: tuple[str, ...] = ("train",)  # episode meta `split` values used for training
    val_fraction: float = 0.1  # held-out episodes for the validation loss
    batch_size: int = 32
    max_steps: int = 20000
    lr: float = 1e-4
    betas: tuple[float, float] = (0.95, 0.999)
    weight_decay: float = 1e-6
    warmup_steps: int = 500
    ema: bool = True  # keep an exponential moving average of the weights (used for validation and evaluation)
    ema_power: float = 0.75
    ema_max_decay: float = 0.9999
    cache_points_per_object: int = 512
    log_every: int = 50
    val_every: int = 500
    val_batches: int = 8
    checkpoint_every: int = 500
    keep_every: int = 0  # also keep step_<N>.pt every N steps (0 = only last.pt)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)  # MLflow besides metrics.csv (grits_lab/training/metrics_log.py)

    def __post_init__(self) -> None:
        require(self.batch_size >= 1, "batch_size", self.batch_size, "at least 1")
        require(self.max_steps >= 1, "max_steps", self.max_steps, "at least 1")
        require(self.lr > 0, "lr", self.lr, "positive")
        require(0 <= self.val_fraction < 1, "val_fraction", self.val_fraction, "in [0, 1)")
        require(self.warmup_steps >= 0, "warmup_steps", self.warmup_steps, "non-negative")
        for key in ("log_every", "val_every", "checkpoint_every", "val_batches"):
            require(getattr(self, key) >= 1, key, getattr(self, key), "at least 1")
        require(self.keep_every >= 0, "keep_every", self.keep_every, "non-negative")
        require(self.num_threads >= 0, "num_threads", self.num_threads, "non-negative")
        require(1 <= self.num_processes <= self.batch_size, "num_processes", self.num_processes, "between 1 and batch_size")


def to_torch(batch: dict[str, np.ndarray], device: torch.device) -> dict[str, torch.Tensor]:
    """Numpy batch -> tensors on `device`: floats as float32, uint8 images kept as uint8."""
    return {k: torch.from_numpy(v).to(device) if v.dtype == np.uint8 else torch.from_numpy(v).to(device).float() for k, v in batch.items()}


@torch.no_grad()
def validation_loss(policy: nn.Module, dataset: DemoWindowDataset, n_batches: int, batch_size: int, seed: int, device: torch.device) -> float:
    """Mean loss over fixed windows and fixed noise (same seed every time), so values are comparable."""
    was_training = policy.training
    policy.eval()
    rng = np.random.default_rng(seed)
    gen = torch.Generator(device=device).manual_seed(seed)
    losses = []
    for _ in range(n_batches):
        idx = rng.choice(len(dataset), size=min(batch_size, len(dataset)), replace=False)
        losses.append(float(policy.compute_loss(to_torch(dataset.gather(idx), device), gen)))  # type: ignore[operator]
    policy.train(was_training)
    return float(np.mean(losses))


def train_on_demonstrations(
    config: DemoTrainConfig,
    make_policy: Callable[[], nn.Module],
    *,
    desc: str,
    rollout: RolloutSettings | None = None,
    rollouts: RolloutsFactory | None = None,
    max_steps: int | None = None,
    progress: bool = True,
    restart: bool = False,
) -> dict[str, Any]:
    """Train (or resume) `make_policy()` on `config.dataset` and return a summary.

    The policy needs `fit_normalizers`, `compute_loss(batch, generator)`, `policy_state()`,
    `load_state_dict` and `load_normalizer_state`. With `rollout.every` > 0 (diffusion policies only),
    `rollouts(rollout, episodes)` builds the player of the training scoops (the simulator's is
    grits_lab.evaluation.rollouts.ScoopRollouts, handed in by the caller above this layer) and
    they are played every `rollout.every` steps. Raises ConfigError when rollouts are asked for
    and no player was handed in. `max_steps`
    stops the run early; the LR schedule still spans the config's `max_steps`.

    With `num_processes` > 1 and a CPU device the steps run data-parallel in that many processes
    (grits_lab/training/data_parallel.py); `make_policy` must then pickle (a functools.partial of
    the policy class, not a lambda). On a GPU one process trains, with one line on stderr.
    """
    if rollout is not None and rollout.every and rollouts is None:
        raise ConfigError("`rollout.every` asks for scoops during training, but no rollout player was handed to the "
                          "training loop (train through `grits-lab train policy` or the pipeline, which hand in the simulator's)")
    device = resolve_device(config.device)
    if config.num_processes > 1 and device.type != "cpu":
        print(f"num_processes: {config.num_processes} splits batches over CPU cores; training in one process on {device}",
              file=sys.stderr)
    list_demo_episodes(config.dataset, tuple(config.splits))  # a missing dataset fails here, before any directory or process
    out = ensure_writable_dir(config.output_dir)
    with exclusive_directory(out, desc):  # one trainer per run directory: two would overwrite each other's last.pt
        if config.num_processes == 1 or device.type != "cpu":
            return _train(0, 1, config, make_policy, desc, rollout, rollouts, max_steps, progress, restart)
        return run_processes(_train, config.num_processes, (config, make_policy, desc, None, None, max_steps, progress, restart), out)


def _train(
    rank: int,
    world_size: int,
    config: DemoTrainConfig,
    make_policy: Callable[[], nn.Module],
    desc: str,
    rollout: RolloutSettings | None,
    rollouts: RolloutsFactory | None,
    max_steps: int | None,
    progress: bool,
    restart: bool,
) -> dict[str, Any]:
    """The training loop of process `rank` of `world_size`; process 0 alone logs, validates and checkpoints."""
    lead = rank == 0
    set_torch_threads(config.num_threads)
    device = resolve_device(config.device)
    total_steps = min(max_steps or config.max_steps, config.max_steps)
    out = ensure_writable_dir(config.output_dir)
    ckpt_dir = out / "checkpoints"
    last_path = ckpt_dir / "last.pt"
    if lead:
        write_text_atomic(out / "config.yaml", yaml.safe_dump(config_to_dict(config), sort_keys=False))

    episodes = list_demo_episodes(config.dataset, tuple(config.splits))
    train_ids, val_ids = split_demo_episodes(episodes, config.val_fraction, config.seed)
    fingerprint = dataset_fingerprint(config.dataset)
    policy_config = config.policy  # type: ignore[attr-defined]
    show = progress and lead
    train_set = DemoWindowDataset(config.dataset, train_ids, policy_config, config.cache_points_per_object, config.seed, show)
    val_set = DemoWindowDataset(config.dataset, val_ids, policy_config, config.cache_points_per_object, config.seed + 1, show) if val_ids and lead else None

    torch.manual_seed(config.seed)
    policy = make_policy()
    policy.fit_normalizers(train_set.all_actions(), train_set.all_poses(), train_set.all_cloud_points(seed=config.seed))  # type: ignore[operator]
    policy.to(device).train()
    optimizer = torch.optim.AdamW(policy.parameters(), lr=config.lr, betas=tuple(config.betas), weight_decay=config.weight_decay,
                                  fused=device.type in ("cpu", "cuda"))  # one kernel for all parameters: 3 ms, not 12, on the cpu preset
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda s: warmup_cosine(s, config.warmup_steps, config.max_steps))
    ema = EMA(policy, power=config.ema_power, max_decay=config.ema_max_decay) if config.ema and lead else None
    evaluated = ema.model if ema is not None else policy  # the weights validation and rollouts judge
    gen = torch.Generator(device=device).manual_seed(config.seed + rank)  # each process draws its own noise
    step = 0

    if last_path.exists() and not restart:
        ckpt = load_checkpoint(last_path, map_location=device)
        if ckpt.get("dataset_fingerprint") != fingerprint:
            raise StorageError(
                f"{last_path} was trained on different data (fingerprint {ckpt.get('dataset_fingerprint')} != {fingerprint}); "
                "use --restart to start over or another output_dir"
            )
        policy.load_state_dict(ckpt["policy"]["model"])
        policy.load_normalizer_state(ckpt["policy"]["normalizers"])  # type: ignore[operator]
        optimizer.load_state_dict(ckpt["optimizer"])
        scheduler.load_state_dict(ckpt["lr_scheduler"])
        if ema is not None:
            ema.load_state_dict(ckpt["ema"])
        step = int(ckpt["step"])
        states = ckpt.get("torch_rng_processes") or [ckpt["torch_rng"]]  # checkpoints written before data-parallel training
        if len(states) == world_size:
            gen.set_state(states[rank])
        else:  # another process count: fresh noise streams, determined by (seed, rank, step)
            gen.manual_seed(int(np.random.default_rng([config.seed, rank, step]).integers(1 << 62)))

    def checkpoint() -> None:
        rng_states = [gen.get_state()]
        if world_size > 1:
            rng_states = [None] * world_size
            torch.distributed.all_gather_object(rng_states, gen.get_state())
        if not lead:
            return
        state = {
            "protocol": PROTOCOL,  # the task protocol of the code that trained it (docs/protocol.md)
            CPU_KERNELS: cpu_kernels(),  # what trained it: weights trained on other kernels differ (docs/evaluation.md)
            "policy": policy.policy_state(),  # type: ignore[operator]
            "ema": ema.state_dict() if ema is not None else None,
            "optimizer": optimizer.state_dict(),
            "lr_scheduler": scheduler.state_dict(),
            "step": step,
            "torch_rng_processes": rng_states,  # one noise generator state per process
            "train_config": config_to_dict(config),
            "config_fingerprint": config_fingerprint(policy_config),
            "dataset_fingerprint": fingerprint,
            "train_episodes": train_ids,
            "val_episodes": val_ids,
        }
        save_checkpoint(last_path, state)
        if config.keep_every and step % config.keep_every == 0:
            save_checkpoint(ckpt_dir / f"step_{step}.pt", state)

    player = None
    if rollout is not None and rollout.every:
        from grits_lab.data.format import load_index

        train_set_ids = set(train_ids)
        pairs = [(r.food, r.level) for r in load_index(config.dataset).itertuples() if r.episode_id in train_set_ids]
        player = rollouts(rollout, rollout_episodes(pairs, rollout.episodes, config.seed))  # type: ignore[misc]
    logger = MetricLogger(out, namespace=desc.removeprefix("train "), resume_step=step, title=f"{desc} {Path(out).name}",
                          tracking=config.tracking, params=config_to_dict(config)) if lead else None
    first_loss = last_loss = float("nan")
    window: list[float] = []
    started = time.perf_counter()
    start_step = step
    bar = tqdm(total=total_steps, initial=step, desc=desc, disable=not show, dynamic_ncols=True)
    try:
        while step < total_steps:
            indices, share = batch_share(train_set.batch_indices(step, config.batch_size, config.seed), rank, world_size)
            loss = policy.compute_loss(to_torch(train_set.gather(indices), device), gen)  # type: ignore[operator]
            require_finite_loss(loss, f"step {step + 1}", last_path)
            optimizer.zero_grad(set_to_none=True)
            (loss * share).backward()
            batch_loss = reduce_gradients(policy, loss * share) if world_size > 1 else loss.item()
            optimizer.step()
            scheduler.step()
            if ema is not None:
                ema.update(policy)
            step += 1
            window.append(batch_loss)
            if np.isnan(first_loss):
                first_loss = window[-1]
            bar.update(1)
            if lead and (step % config.log_every == 0 or step == total_steps):
                last_loss = float(np.mean(window))
                rate = (step - start_step) / max(time.perf_counter() - started, 1e-9)
                values = {"train_loss": last_loss, "lr": scheduler.get_last_lr()[0], "steps_per_s": rate}
                if val_set is not None and (step % config.val_every == 0 or step == total_steps):
                    values["val_loss"] = validation_loss(evaluated, val_set, config.val_batches, config.batch_size, config.seed, device)
                if player is not None and (step % rollout.every == 0 or step == total_steps):  # type: ignore[union-attr]
                    values.update(player(evaluated))
                logger.log(step, values)  # type: ignore[union-attr]
                bar.set_postfix({k: f"{v:.4g}" for k, v in values.items() if k != "lr"})
                window = []
            if step % config.checkpoint_every == 0 or step == total_steps:
                checkpoint()
    finally:
        bar.close()
        if logger is not None:
            logger.close()
        if player is not None:
            player.close()
    return {
        "output_dir": str(out),
        "checkpoint": str(last_path),
        "steps": step,
        "resumed_from": start_step,
        "first_loss": first_loss,
        "final_train_loss": last_loss,
        "train_episodes": len(train_ids),
        "val_episodes": len(val_ids),
        "windows": len(train_set),
        "seconds": time.perf_counter() - started,
        "device": str(device),
        "num_processes": world_size,
    }
