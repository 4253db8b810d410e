"""Training of the behavior-cloning baseline on the demonstrations the diffusion policy learns from.

Same data pipeline as the diffusion policy (demo windows, held-out episodes, batches determined
by (seed, step)), the authors' optimizer settings, and `checkpoints/last.pt` written atomically;
running the same config again resumes from it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml
from tqdm import tqdm

from grits_lab.config import config_to_dict, load_config, require
from grits_lab.errors import StorageError
from grits_lab.io import ensure_writable_dir, write_text_atomic
from grits_lab.policies.bc.configuration_bc import BCConfig
from grits_lab.policies.bc.modeling_bc import BCPolicy
from grits_lab.policies.diffusion.dataset import DemoWindowDataset, dataset_fingerprint, list_demo_episodes, split_episodes
from grits_lab.policies.diffusion.training import validation_loss
from grits_lab.training import MetricLogger, load_checkpoint, resolve_device, save_checkpoint, set_torch_threads, warmup_cosine


@dataclass
class BCTrainConfig:
    dataset: str
    output_dir: str
    policy: BCConfig = field(default_factory=BCConfig)
    seed: int = 0
    device: str = "auto"
    num_threads: int = 2
    splits: tuple[str, ...] = ("train",)
    val_fraction: float = 0.1
    batch_size: int = 32
    max_steps: int = 5000
    lr: float = 1e-4
    weight_decay: float = 1e-6
    warmup_steps: int = 200
    cache_points_per_object: int = 512
    log_every: int = 50
    val_every: int = 500
    val_batches: int = 4
    checkpoint_every: int = 500

    def __post_init__(self) -> None:
        require(self.batch_size >= 1, "batch_size", self.batch_size, "at least 1")
        require(self.max_steps >= 1, "max_steps", self.max_steps, "at least 1")
        require(self.lr > 0, "lr", self.lr, "positive")
        require(0 <= self.val_fraction < 1, "val_fraction", self.val_fraction, "in [0, 1)")
        for key in ("log_every", "val_every", "checkpoint_every", "val_batches"):
            require(getattr(self, key) >= 1, key, getattr(self, key), "at least 1")


def load_bc_config(path: str | Path) -> BCTrainConfig:
    return load_config(path, BCTrainConfig)


def _to_torch(batch: dict[str, np.ndarray], device: torch.device) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(v).to(device) if v.dtype == np.uint8 else torch.from_numpy(v).to(device).float() for k, v in batch.items()}


def train_bc(config: BCTrainConfig, max_steps: int | None = None, progress: bool = True, fresh: bool = False) -> dict[str, Any]:
    """Train (or resume) the BC policy; returns a summary with the first and last training loss."""
    set_torch_threads(config.num_threads)
    device = resolve_device(config.device)
    total = max_steps or config.max_steps
    out = ensure_writable_dir(config.output_dir)
    last_path = out / "checkpoints" / "last.pt"
    write_text_atomic(out / "config.yaml", yaml.safe_dump(config_to_dict(config), sort_keys=False))
    episodes = list_demo_episodes(config.dataset, tuple(config.splits))
    train_ids, val_ids = split_episodes(episodes, config.val_fraction, config.seed)
    fingerprint = dataset_fingerprint(config.dataset)
    # DemoWindowDataset reads horizon, n_obs_steps and obs_encoder, which BCConfig names alike.
    train_set = DemoWindowDataset(config.dataset, train_ids, config.policy, config.cache_points_per_object, config.seed, progress)  # type: ignore[arg-type]
    val_set = DemoWindowDataset(config.dataset, val_ids, config.policy, config.cache_points_per_object, config.seed + 1, progress) if val_ids else None  # type: ignore[arg-type]

    torch.manual_seed(config.seed)
    policy = BCPolicy(config.policy)
    policy.fit_normalizers(train_set.all_actions(), train_set.all_poses(), train_set.all_cloud_points(seed=config.seed))
    policy.to(device).train()
    optimizer = torch.optim.AdamW(policy.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    scheduler = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda s: warmup_cosine(s, config.warmup_steps, total))
    gen = torch.Generator(device=device).manual_seed(config.seed)
    step = 0
    if last_path.exists() and not fresh:
        ckpt = load_checkpoint(last_path, map_location=device)
        if ckpt.get("dataset_fingerprint") != fingerprint:
            raise StorageError(f"{last_path} was trained on different data; use --fresh or another output_dir")
        policy.load_state_dict(ckpt["policy"]["model"])
        policy.load_normalizer_state(ckpt["policy"]["normalizers"])
        optimizer.load_state_dict(ckpt["optimizer"])
        scheduler.load_state_dict(ckpt["lr_scheduler"])
        gen.set_state(ckpt["torch_rng"])
        step = int(ckpt["step"])

    def checkpoint() -> None:
        save_checkpoint(last_path, {
            "policy": policy.policy_state(), "optimizer": optimizer.state_dict(), "lr_scheduler": scheduler.state_dict(),
            "step": step, "torch_rng": gen.get_state(), "train_config": config_to_dict(config),
            "dataset_fingerprint": fingerprint, "train_episodes": train_ids, "val_episodes": val_ids,
        })

    logger = MetricLogger(out, resume_step=step, tensorboard=False)
    first = last = float("nan")
    window: list[float] = []
    started, start_step = time.perf_counter(), step
    bar = tqdm(total=total, initial=step, desc="train bc", disable=not progress, dynamic_ncols=True)
    try:
        while step < total:
            batch = _to_torch(train_set.gather(train_set.batch_indices(step, config.batch_size, config.seed)), device)
            loss = policy.compute_loss(batch, gen)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            scheduler.step()
            step += 1
            window.append(loss.item())
            first = window[-1] if np.isnan(first) else first
            bar.update(1)
            if step % config.log_every == 0 or step == total:
                last = float(np.mean(window))
                values = {"train_loss": last, "lr": scheduler.get_last_lr()[0]}
                if val_set is not None and (step % config.val_every == 0 or step == total):
                    values["val_loss"] = validation_loss(policy, val_set, config.val_batches, config.batch_size, config.seed, device)  # type: ignore[arg-type]
                logger.log(step, values)
                bar.set_postfix({k: f"{v:.4g}" for k, v in values.items() if k != "lr"})
                window = []
            if step % config.checkpoint_every == 0 or step == total:
                checkpoint()
    finally:
        bar.close()
        logger.close()
    return {"output_dir": str(out), "checkpoint": str(last_path), "steps": step, "resumed_from": start_step,
            "first_loss": first, "final_train_loss": last, "train_episodes": len(train_ids), "val_episodes": len(val_ids),
            "seconds": time.perf_counter() - started}
