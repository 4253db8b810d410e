"""Training of the behavior-cloning baseline on the demonstrations the diffusion policy learns from.

The diffusion policy's demonstration loop (grits_lab/policies/demo_training.py): the same demo
windows, held-out episodes, batches determined by (seed, step), atomic `checkpoints/last.pt` and
exact resume. BC keeps no EMA (a deterministic regression is judged by its own weights) and
AdamW's default betas.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

from grits_lab.config import load_config
from grits_lab.policies.bc.configuration_bc import BCConfig
from grits_lab.policies.bc.modeling_bc import BCPolicy
from grits_lab.policies.demo_training import DemoTrainConfig, train_on_demonstrations


@dataclass
class BCTrainConfig(DemoTrainConfig):
    policy: BCConfig = field(default_factory=BCConfig)
    max_steps: int = 5000
    betas: tuple[float, float] = (0.9, 0.999)
    warmup_steps: int = 200
    ema: bool = False
    val_batches: int = 4


def load_bc_config(path: str | Path) -> BCTrainConfig:
    return load_config(path, BCTrainConfig)


def train_bc(config: BCTrainConfig, max_steps: int | None = None, progress: bool = True, restart: bool = False) -> dict[str, Any]:
    """Train (or resume) the BC policy; returns a summary with the first and last training loss."""
    return train_on_demonstrations(config, partial(BCPolicy, config.policy), desc="train bc", max_steps=max_steps,
                                   progress=progress, restart=restart)
