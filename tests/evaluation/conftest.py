"""Tiny real models for evaluation tests: a diffusion policy, a BC policy and a spillage predictor trained
for a few seconds on small datasets built from the sim's own scoop geometry (no mocks of the sim)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from grits_lab.config import config_from_dict
from grits_lab.data.format import MANIFEST_FILE, rebuild_index, write_episode
from grits_lab.sim import SimConfig
from grits_lab.sim.env import scene_geometry
from grits_lab.sim.expert import expert_trajectory

from tests.evaluation.eval_helpers import N_POINTS  # noqa: E402  (shared with the config builder)


def _clouds(rng: np.random.Generator, poses: np.ndarray, bowl: np.ndarray, food_top: float) -> np.ndarray:
    t = len(poses)
    food = bowl + rng.uniform([-0.04, -0.04, 0.006], [0.04, 0.04, food_top], (t, N_POINTS, 3))
    spoon = poses[:, None, :3] + rng.normal(0, 0.01, (t, N_POINTS, 3))
    ang = rng.uniform(0, 2 * np.pi, (t, N_POINTS))
    ring = np.stack([0.08 * np.cos(ang), 0.08 * np.sin(ang), rng.uniform(0.0, 0.065, (t, N_POINTS))], -1)
    return np.stack([food, spoon, bowl + ring], axis=1).astype(np.float16)


def write_demos(root: Path, n: int = 4) -> Path:
    """Expert scoops of this scene (the sim's own keyframes, randomized per seed), with synthetic clouds."""
    sim = SimConfig()
    scene = scene_geometry(sim, np.array(sim.target_workspace_center))
    bowl = np.array(scene.source_bowl_center)
    for i in range(n):
        rng = np.random.default_rng(i)
        action = expert_trajectory(scene, rng).astype(np.float32)
        ee_pose = np.concatenate([np.array(scene.spoon_home, dtype=np.float32)[None], action[:-1]])
        cloud = _clouds(rng, ee_pose, bowl, 0.02)
        write_episode(root, f"ep{i:03d}", {"action": action, "ee_pose": ee_pose, "joint_pos": np.zeros((len(action), 7), np.float32), "cloud": cloud},
                      {"food": "soybeans", "split": "train", "level": "medium", "seed": i})
    rebuild_index(root)
    return root


def write_spillage(root: Path, demos: Path, n: int = 16) -> Path:
    """Chunks of shifted expert scoops labelled by a rule that needs both trajectory and cloud:
    a chunk spills when the spoon passes more than 1 cm below the food's top."""
    sim = SimConfig()
    scene = scene_geometry(sim, np.array(sim.target_workspace_center))
    bowl = np.array(scene.source_bowl_center)
    root.mkdir(parents=True, exist_ok=True)
    (root / MANIFEST_FILE).write_text(yaml.safe_dump({"format_version": 1, "kind": "spillage"}))
    for e in range(n):
        rng = np.random.default_rng(100 + e)
        traj = expert_trajectory(scene, rng).astype(np.float32)
        traj[:, 2] += rng.uniform(-0.01, 0.03)
        food_top = rng.uniform(0.015, 0.04)
        starts = np.arange(0, len(traj) - 12, 12, dtype=np.int32)
        spilled = np.array([traj[s : s + 12, 2].min() < bowl[2] + food_top - 0.01 for s in starts])
        cloud = _clouds(rng, traj[starts], bowl, food_top)
        write_episode(root, f"ep_{e:06d}", {"trajectory": traj, "chunk_start": starts, "chunk_cloud": cloud, "chunk_cloud_raw": cloud,
                                            "chunk_spilled": spilled, "spilled_over_time": np.zeros(len(traj), np.int32)},
                      {"shape": "sphere", "seed": e, "label": int(spilled.any()), "split": "train"})
    rebuild_index(root)
    return root


@pytest.fixture(scope="session")
def models(tmp_path_factory) -> dict[str, str]:
    """Paths of tiny trained checkpoints: diffusion policy, BC policy, predictor; and the demos."""
    from grits_lab.policies.bc.training_bc import BCTrainConfig, train_bc
    from grits_lab.policies.diffusion.training_diffusion import PolicyTrainConfig, train_policy
    from grits_lab.spillage.predictor_config import PredictorConfig
    from grits_lab.spillage.predictor_training import train_predictor

    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("eval-models")
    demos = write_demos(root / "demos")
    spill = write_spillage(root / "spill", demos)
    policy = {"horizon": 16, "n_obs_steps": 2, "n_action_steps": 12,
              "obs_encoder": {"kind": "pointcloud", "points_per_object": 16, "point_hidden": [16], "feature_dim": 8, "cloud_steps": 1}}
    dp_cfg = config_from_dict(PolicyTrainConfig, {
        "dataset": str(demos), "output_dir": str(root / "dp"), "batch_size": 16, "max_steps": 40, "lr": 1e-3, "warmup_steps": 5,
        "val_fraction": 0.0, "log_every": 20, "checkpoint_every": 40, "num_threads": 1, "cache_points_per_object": N_POINTS,
        "policy": {**policy, "inpaint_past_actions": True,  # the whole episode path with past-action conditioning
                   "unet": {"down_dims": [16, 32], "kernel_size": 3, "n_groups": 4, "diffusion_step_embed_dim": 16}},
    })
    train_policy(dp_cfg, progress=False)
    bc_cfg = config_from_dict(BCTrainConfig, {
        "dataset": str(demos), "output_dir": str(root / "bc"), "batch_size": 16, "max_steps": 40, "lr": 1e-3, "warmup_steps": 5,
        "val_fraction": 0.0, "log_every": 20, "checkpoint_every": 40, "num_threads": 1, "cache_points_per_object": N_POINTS,
        "policy": {**policy, "hidden": [32]},
    })
    train_bc(bc_cfg, progress=False)
    pred_cfg = config_from_dict(PredictorConfig, {
        "name": "tiny", "output_dir": str(root / "predictor"),
        "model": {"dp3": {"hidden_dims": [16, 32], "out_dim": 16}, "fusion_mlp": [32, 16]},
        "data": {"dataset": str(spill), "points_per_object": 16, "val_fraction": 0.25},
        "train": {"epochs": 3, "batch_size": 16, "num_threads": 1},
    })
    train_predictor(pred_cfg, progress=False)
    return {"policy": str(root / "dp" / "checkpoints" / "last.pt"), "bc": str(root / "bc" / "checkpoints" / "last.pt"),
            "predictor": str(root / "predictor" / "tiny" / "best.pt"), "demos": str(demos)}


@pytest.fixture(scope="session")
def recorded_run(models, tmp_path_factory):
    """A recorded `grits-lab evaluate` run directory: dp and grits on one episode; (run_dir, records)."""
    from tests.evaluation.eval_helpers import eval_config
    from grits_lab.evaluation.evaluation_run import evaluate

    config = eval_config(models, tmp_path_factory.mktemp("recorded-run"), methods=["dp", "grits"])
    records = evaluate(config, progress=False)
    assert (records["error"] == "").all()
    return Path(config.output_dir), records
