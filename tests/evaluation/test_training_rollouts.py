"""Scoops played during policy training: logged next to the losses, the same episodes every time."""

from __future__ import annotations

import pandas as pd
import torch

from tests.evaluation.eval_helpers import N_POINTS
from grits_lab.config import config_from_dict
from grits_lab.evaluation.rollouts import ScoopRollouts
from grits_lab.policies.control import RolloutSettings, rollout_episodes
from grits_lab.policies.diffusion import DiffusionPolicy
from grits_lab.policies.diffusion.training_diffusion import PolicyTrainConfig, train_policy

ROLLOUT = {"every": 10, "episodes": 2, "scoop": {"max_steps": 24, "min_steps": 12, "settle_steps": 1},
           "cloud": {"n_points": N_POINTS, "cad_surface_samples": 1000}}


def test_training_logs_scoop_rates_from_the_sim_and_they_repeat_for_the_same_weights(models, tmp_path):
    torch.set_num_threads(1)
    demos = models["demos"]  # expert scoops of the sim's scene (tests/evaluation/conftest.py)
    config = config_from_dict(PolicyTrainConfig, {
        "dataset": demos, "output_dir": str(tmp_path / "dp"), "batch_size": 8, "max_steps": 20, "warmup_steps": 2,
        "val_fraction": 0.0, "log_every": 10, "checkpoint_every": 20, "num_threads": 1, "cache_points_per_object": N_POINTS,
        "rollout": ROLLOUT,
        "policy": {"horizon": 16, "n_obs_steps": 2, "n_action_steps": 12, "inpaint_past_actions": True,
                   "obs_encoder": {"kind": "pointcloud", "points_per_object": 16, "point_hidden": [16], "feature_dim": 8},
                   "unet": {"down_dims": [16, 32], "kernel_size": 3, "n_groups": 4, "diffusion_step_embed_dim": 16}},
    })
    summary = train_policy(config, progress=False, rollouts=ScoopRollouts)
    log = pd.read_csv(tmp_path / "dp" / "metrics.csv")
    assert list(log["step"]) == [10, 20]
    assert log["rollout_scoop_success"].between(0, 1).all() and log["rollout_spillage"].between(0, 1).all()

    episodes = rollout_episodes([("soybeans", "medium")], 2, seed=0)
    assert episodes == rollout_episodes([("soybeans", "medium")] * 3, 2, seed=0) and episodes[0][2] != episodes[1][2]
    policy = DiffusionPolicy.load(summary["checkpoint"])
    policy.train()
    rollouts = ScoopRollouts(config_from_dict(RolloutSettings, ROLLOUT), episodes)
    try:
        first, second = rollouts(policy), rollouts(policy)
    finally:
        rollouts.close()
    assert first == second and policy.training  # same weights, same scenes, same noise: same rates; mode restored
    assert first == log.iloc[-1][["rollout_scoop_success", "rollout_spillage"]].to_dict()


def test_rollouts_asked_for_without_a_player_fail_before_training(tmp_path):
    import pytest

    from grits_lab.errors import ConfigError

    config = config_from_dict(PolicyTrainConfig, {"dataset": str(tmp_path / "none"), "output_dir": str(tmp_path / "dp"),
                                                  "log_every": 10, "rollout": ROLLOUT})
    with pytest.raises(ConfigError, match="no rollout player"):
        train_policy(config, progress=False)
    assert not (tmp_path / "dp").exists()
