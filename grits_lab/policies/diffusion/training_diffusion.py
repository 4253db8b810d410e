"""Training of the diffusion policy: its experiment config, on the shared demonstration loop.

The loop (EMA, validation, checkpoints, exact resume, optional sim rollouts) is
grits_lab/policies/demo_training.py; this module names what the diffusion policy adds: its
policy config, the EMA it is evaluated with, and scoops played during training.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

from grits_lab.config import load_config, require
from grits_lab.policies.control import RolloutSettings, RolloutsFactory
from grits_lab.policies.demo_training import DemoTrainConfig, train_on_demonstrations
from grits_lab.policies.diffusion.configuration_diffusion import DiffusionPolicyConfig
from grits_lab.policies.diffusion.modeling_diffusion import DiffusionPolicy

__all__ = ["PolicyTrainConfig", "load_train_config", "train_policy"]


@dataclass
class PolicyTrainConfig(DemoTrainConfig):
    """An experiment: which data, which policy, how long; authors' optimizer settings and EMA by default."""

    policy: DiffusionPolicyConfig = field(default_factory=DiffusionPolicyConfig)
    # Every `rollout.every` steps (0 = never) play `rollout.episodes` scoops in the simulator with
    # the EMA weights and log rollout_scoop_success / rollout_spillage (played by the caller's `rollouts`, e.g. grits_lab/evaluation/rollouts.py).
    rollout: RolloutSettings = field(default_factory=RolloutSettings)

    def __post_init__(self) -> None:
        super().__post_init__()
        require(self.rollout.every % self.log_every == 0, "rollout.every", self.rollout.every,
                f"a multiple of log_every={self.log_every} (rates are logged with the losses)")
        require(not (self.rollout.every and self.num_processes > 1), "rollout.every", self.rollout.every,
                f"0 when num_processes is {self.num_processes} (scoops during training are played in one process)")


def load_train_config(path: str | Path) -> PolicyTrainConfig:
    return load_config(path, PolicyTrainConfig)


def train_policy(config: PolicyTrainConfig, max_steps: int | None = None, progress: bool = True, restart: bool = False,
                 rollouts: RolloutsFactory | None = None) -> dict[str, Any]:
    """Train (or resume) the diffusion policy and return a summary.

    `max_steps` stops the run early (the LR schedule still spans the config's `max_steps`, so a
    run stopped and resumed ends where an uninterrupted one does). `rollouts` plays the training
    scoops when `config.rollout.every` > 0 (grits_lab.evaluation.rollouts.ScoopRollouts).
    """
    return train_on_demonstrations(config, partial(DiffusionPolicy, config.policy), desc="train policy", rollout=config.rollout, rollouts=rollouts,
                                   max_steps=max_steps, progress=progress, restart=restart)
