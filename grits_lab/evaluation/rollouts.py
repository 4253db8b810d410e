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

from typing import Any

import numpy as np

from grits_lab.policies.control import RolloutSettings


class ScoopRollouts:
    """`grits_lab.policies.control.Rollouts` in the simulator: a simulator and cloud builder kept for the whole run; `__call__(policy)` plays the scoops."""

    def __init__(self, settings: RolloutSettings, episodes: list[tuple[str, str, int]]) -> None:
        from grits_lab.perception.env_clouds import builder_for_env
        from grits_lab.sim import ScoopEnv

        self.settings = settings
        self.episodes = episodes
        self.env = ScoopEnv(settings.sim)
        self.builder = builder_for_env(settings.cloud, self.env)

    def __call__(self, policy: Any) -> dict[str, float]:
        """Scoop success and spillage rates of `policy` (put in eval mode for the rollouts) over the episodes."""
        from grits_lab.evaluation.controllers import DiffusionController
        from grits_lab.evaluation.task_episode import begin_episode, run_scoop

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
