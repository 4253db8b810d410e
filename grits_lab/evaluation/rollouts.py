"""Scoop-only rollouts of a policy while it trains: how often it scoops, measured in the simulator.

The validation loss says how well the network denoises held-out demonstrations, not whether the
spoon ends up holding food: a small loss can still hide a jump at a chunk boundary that empties
the spoon. Training can therefore play a few scoops every N steps with the EMA weights and log
the scoop success and spillage rates next to the losses.

The episodes are fixed for a run (foods and levels of the training demonstrations in turn, seeds
derived from the training seed), so the rates of two checkpoints compare the same scenes. They
run in the training process, one after another: a handful of scoops costs tens of seconds of one
core, which is why this is off unless asked for.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from grits_lab.config import require
from grits_lab.evaluation.config import ScoopSettings
from grits_lab.perception.composite import CloudConfig
from grits_lab.seeding import derive_seed


@dataclass
class RolloutSettings:
    """Scoops played during training (`every` steps; 0 = never)."""

    every: int = 0
    episodes: int = 6
    scoop: ScoopSettings = field(default_factory=ScoopSettings)
    cloud: CloudConfig = field(default_factory=lambda: CloudConfig(n_points=256, cad_surface_samples=4000))
    sim: dict[str, Any] = field(default_factory=dict)  # grits_lab.sim.SimConfig keys

    def __post_init__(self) -> None:
        require(self.every >= 0, "rollout.every", self.every, "non-negative (0 = never)")
        require(self.episodes >= 1, "rollout.episodes", self.episodes, "at least 1")


def rollout_episodes(pairs: list[tuple[str, str]], n: int, seed: int) -> list[tuple[str, str, int]]:
    """(food, level, seed) of the `n` scoops: the (food, level) pairs in turn, seeds derived from `seed`."""
    ordered = sorted(set(pairs))
    return [(*ordered[i % len(ordered)], derive_seed(seed, "rollout", i)) for i in range(n)]


class ScoopRollouts:
    """A simulator and cloud builder kept for the whole run; `__call__(policy)` plays the scoops."""

    def __init__(self, settings: RolloutSettings, episodes: list[tuple[str, str, int]]) -> None:
        from grits_lab.config import config_from_dict
        from grits_lab.perception.scene import builder_for_env
        from grits_lab.sim import ScoopEnv, SimConfig

        self.settings = settings
        self.episodes = episodes
        self.env = ScoopEnv(config_from_dict(SimConfig, settings.sim, "rollout.sim"))
        self.builder = builder_for_env(settings.cloud, self.env)

    def __call__(self, policy: Any) -> dict[str, float]:
        """Scoop success and spillage rates of `policy` (put in eval mode for the rollouts) over the episodes."""
        from grits_lab.evaluation.controllers import DiffusionController
        from grits_lab.evaluation.episode import begin_episode, run_scoop

        was_training = policy.training
        policy.eval()
        controller = DiffusionController(policy, None, "plain", None, None)
        success, spilled = [], []
        try:
            for food, level, seed in self.episodes:
                scene, history = begin_episode(self.env, self.builder, seed=seed, food=food, level=level)
                metrics = run_scoop(self.env, controller, scene, history, self.settings.scoop)["metrics"]
                success.append(bool(metrics["scoop_success"]))
                spilled.append(int(metrics["spilled"]) > 0)
        finally:
            policy.train(was_training)
        return {"rollout_scoop_success": float(np.mean(success)), "rollout_spillage": float(np.mean(spilled))}

    def close(self) -> None:
        self.env.close()
