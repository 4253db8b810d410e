"""Diffusion policy: windows, learning, checkpoints, resume, the injected sampler, bad input."""

import numpy as np
import pandas as pd
import pytest
import torch

from grits_lab.config import config_from_dict
from grits_lab.errors import ConfigError, InputError, StorageError
from grits_lab.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig
from grits_lab.policies.diffusion.demo_windows import DemoWindowDataset, list_demo_episodes, split_demo_episodes
from grits_lab.policies.diffusion.training_diffusion import PolicyTrainConfig, train_policy
from grits_lab.sampling import DDIMSampler, GuidanceConfig

torch.set_num_threads(1)

TINY_POLICY = {
    "horizon": 16,
    "n_obs_steps": 2,
    "n_action_steps": 12,
    "obs_encoder": {"kind": "pointcloud", "points_per_object": 16, "point_hidden": [16, 32], "feature_dim": 16},
    "unet": {"down_dims": [16, 32], "kernel_size": 3, "n_groups": 4, "diffusion_step_embed_dim": 16},
}


def _train_config(dataset, out, **overrides):
    raw = {
        "dataset": str(dataset),
        "output_dir": str(out),
        "policy": TINY_POLICY,
        "device": "cpu",
        "num_threads": 1,
        "batch_size": 16,
        "max_steps": 20,
        "lr": 1e-3,
        "warmup_steps": 5,
        "log_every": 5,
        "val_every": 10,
        "val_batches": 1,
        "checkpoint_every": 10,
        "cache_points_per_object": 32,
        **overrides,
    }
    return config_from_dict(PolicyTrainConfig, raw)


def test_windows_pad_with_edge_values_and_align_obs_with_actions(demo_dataset):
    cfg = config_from_dict(DiffusionPolicyConfig, TINY_POLICY)
    ds = DemoWindowDataset(demo_dataset, ["ep000"], cfg, cache_points_per_object=32, progress=False)
    actions = ds.episodes[0].arrays["action"]
    first = ds.window(0)
    # at step 0 the action before the start is the resting pose, the observation repeats step 0
    np.testing.assert_array_equal(first["action"][0, 0], ds.episodes[0].arrays["ee_pose"][0])
    np.testing.assert_array_equal(first["ee_pose"][0, 0], first["ee_pose"][0, 1])
    np.testing.assert_array_equal(first["action"][0, 1], actions[0])
    np.testing.assert_array_equal(first["action"][0, 2], actions[1])
    last = ds.window(len(ds) - 1)
    np.testing.assert_array_equal(last["action"][0, -1], actions[-1])
    assert first["cloud"].shape == (1, 2, 3, 32, 3)
    # the executed chunk starts at the current step
    c = 5
    np.testing.assert_array_equal(ds.window(c)["action"][0, cfg.action_start], actions[c])


def test_split_is_stable_and_disjoint():
    ids = [f"ep{i}" for i in range(20)]
    train, val = split_demo_episodes(ids, 0.2, seed=0)
    assert len(val) == 4 and not set(train) & set(val) and sorted(train + val) == sorted(ids)
    assert split_demo_episodes(list(reversed(ids)), 0.2, seed=0) == (train, val)
    assert split_demo_episodes(ids, 0.2, seed=1)[1] != val


def test_policy_overfits_a_tiny_dataset(tiny_dataset, tmp_path):
    torch.manual_seed(0)
    cfg = config_from_dict(DiffusionPolicyConfig, {**TINY_POLICY, "unet": {**TINY_POLICY["unet"], "down_dims": [32, 64]}})
    ds = DemoWindowDataset(tiny_dataset, list_demo_episodes(tiny_dataset), cfg, cache_points_per_object=16, progress=False)
    policy = DiffusionPolicy(cfg)
    policy.fit_normalizers(ds.all_actions(), ds.all_poses(), ds.all_cloud_points())
    optimizer = torch.optim.AdamW(policy.parameters(), lr=2e-3)
    batch = {k: torch.from_numpy(v).float() for k, v in ds.gather(np.arange(len(ds))).items()}
    gen = torch.Generator().manual_seed(0)
    # the loss at fixed noise draws, averaged, so one lucky draw cannot pass the test
    evaluate = lambda: np.mean([policy.compute_loss(batch, torch.Generator().manual_seed(s)).item() for s in range(4)])
    first = evaluate()
    for _ in range(400):
        loss = policy.compute_loss(batch, gen)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    last = evaluate()
    assert last < first / 10, (first, last)


def test_train_writes_logs_and_checkpoint_round_trip_gives_identical_actions(demo_dataset, tmp_path):
    summary = train_policy(_train_config(demo_dataset, tmp_path / "run"), progress=False)
    assert summary["steps"] == 20 and summary["val_episodes"] == 1
    log = pd.read_csv(tmp_path / "run" / "metrics.csv")
    assert list(log["step"]) == [5, 10, 15, 20] and log["val_loss"].notna().sum() == 2
    assert (tmp_path / "run" / "curves.png").stat().st_size > 0
    a = DiffusionPolicy.load(summary["checkpoint"])
    b = DiffusionPolicy.load(summary["checkpoint"])
    ds = DemoWindowDataset(demo_dataset, ["ep001"], a.config, cache_points_per_object=32, progress=False)
    obs = {k: v[0] for k, v in ds.window(3).items() if k != "action"}
    act_a = a.predict_action(obs, generator=torch.Generator().manual_seed(4))
    act_b = b.predict_action(obs, generator=torch.Generator().manual_seed(4))
    assert act_a.shape == (12, 9) and np.array_equal(act_a, act_b)
    other = a.predict_action(obs, generator=torch.Generator().manual_seed(5))
    assert not np.array_equal(act_a, other)
    batched = a.predict_action({k: np.stack([v, v]) for k, v in obs.items()}, generator=torch.Generator().manual_seed(4))
    assert batched.shape == (2, 12, 9)
    # EMA weights differ from the raw weights after training
    raw = DiffusionPolicy.load(summary["checkpoint"], use_ema=False)
    assert not np.array_equal(raw.predict_action(obs, generator=torch.Generator().manual_seed(4)), act_a)


def test_resume_continues_to_the_same_weights(demo_dataset, tmp_path):
    straight = train_policy(_train_config(demo_dataset, tmp_path / "a"), progress=False)
    train_policy(_train_config(demo_dataset, tmp_path / "b"), max_steps=10, progress=False)
    resumed = train_policy(_train_config(demo_dataset, tmp_path / "b"), progress=False)
    assert resumed["resumed_from"] == 10 and resumed["steps"] == 20
    sa = torch.load(straight["checkpoint"], weights_only=True)
    sb = torch.load(resumed["checkpoint"], weights_only=True)
    for key, value in sa["policy"]["model"].items():
        torch.testing.assert_close(sb["policy"]["model"][key], value, rtol=1e-5, atol=1e-6)
    log = pd.read_csv(tmp_path / "b" / "metrics.csv")
    assert list(log["step"]) == [5, 10, 15, 20]


def test_guided_sampler_plugs_in_and_rho_zero_matches_plain(demo_dataset, tmp_path):
    summary = train_policy(_train_config(demo_dataset, tmp_path / "run", max_steps=5, checkpoint_every=5), progress=False)
    policy = DiffusionPolicy.load(summary["checkpoint"])
    ds = DemoWindowDataset(demo_dataset, ["ep002"], policy.config, cache_points_per_object=32, progress=False)
    obs = {k: v[0] for k, v in ds.window(0).items() if k != "action"}
    cost = lambda traj: traj[:, :, 2].mean(dim=1)  # push the spoon's normalized height down
    plain = policy.plan(obs, generator=torch.Generator().manual_seed(1))
    zero = DDIMSampler(policy.noise_scheduler, GuidanceConfig(rho=0.0))
    same = policy.plan(obs, sampler=zero, objective=cost, generator=torch.Generator().manual_seed(1))
    assert np.array_equal(plain.actions, same.actions)
    guided = DDIMSampler(policy.noise_scheduler, GuidanceConfig(rho=0.5, s=30, compare_unguided=False))
    moved = policy.plan(obs, sampler=guided, objective=cost, generator=torch.Generator().manual_seed(1))
    assert len(moved.result.steps) == 6
    assert moved.actions[:, :, 2].mean() < plain.actions[:, :, 2].mean()


def test_inpainting_holds_the_past_actions_and_the_chunk_continues_from_them(demo_dataset, tmp_path):
    policy_cfg = {**TINY_POLICY, "n_obs_steps": 3, "inpaint_past_actions": True}
    summary = train_policy(_train_config(demo_dataset, tmp_path / "run", policy=policy_cfg, max_steps=5, checkpoint_every=5), progress=False)
    policy = DiffusionPolicy.load(summary["checkpoint"])
    assert policy.config.n_past_actions == 2 and "past_action" in policy.obs_keys
    ds = DemoWindowDataset(demo_dataset, ["ep002"], policy.config, cache_points_per_object=32, progress=False)
    window = ds.window(7)
    obs = {k: v[0] for k, v in window.items() if k != "action"}
    obs["past_action"] = window["action"][0, :2]
    plan = policy.plan(obs, generator=torch.Generator().manual_seed(1))
    known = policy.action_normalizer.normalize(torch.from_numpy(obs["past_action"]).float())
    torch.testing.assert_close(plan.trajectory_norm[0, :2], known)
    # the executed chunk depends on the past actions it continues from
    moved = dict(obs, past_action=obs["past_action"] + np.float32(0.02))
    assert not np.array_equal(policy.plan(moved, generator=torch.Generator().manual_seed(1)).actions, plan.actions)
    plain_cfg = config_from_dict(DiffusionPolicyConfig, {**policy_cfg, "inpaint_past_actions": False})
    assert plain_cfg.n_past_actions == 0
    with pytest.raises(InputError, match="past_action"):
        policy.predict_action({k: v for k, v in obs.items() if k != "past_action"})


def test_bad_inputs_fail_with_one_clear_error(demo_dataset, tmp_path):
    with pytest.raises(ConfigError, match="horizon"):
        config_from_dict(DiffusionPolicyConfig, {"horizon": 8, "n_obs_steps": 2, "n_action_steps": 12})
    with pytest.raises(ConfigError, match="obs_encoder.kind"):
        config_from_dict(DiffusionPolicyConfig, {"obs_encoder": {"kind": "voxels"}})
    with pytest.raises(StorageError, match="not found"):
        train_policy(_train_config(tmp_path / "missing", tmp_path / "out"), progress=False)
    summary = train_policy(_train_config(demo_dataset, tmp_path / "run", max_steps=1), progress=False)
    policy = DiffusionPolicy.load(summary["checkpoint"])
    with pytest.raises(InputError, match="cloud"):
        policy.predict_action({"ee_pose": np.zeros((2, 9))})
    with pytest.raises(InputError, match="NaN"):
        policy.predict_action({"ee_pose": np.full((2, 9), np.nan), "cloud": np.zeros((2, 3, 32, 3))})


@pytest.mark.parametrize("kind", ["rgbd", "lowdim"])
def test_other_encoders_learn_from_their_observation(kind):
    torch.manual_seed(0)
    raw = {
        **TINY_POLICY,
        "obs_encoder": {"kind": kind, "image_size": [64, 64], "resnet_width": 8, "resnet_blocks": [1, 1, 1, 1],
                        "num_keypoints": 4, "feature_dim": 8, "cameras": 2},
    }
    policy = DiffusionPolicy(config_from_dict(DiffusionPolicyConfig, raw))
    rng = np.random.default_rng(0)
    policy.fit_normalizers(rng.uniform(0, 1, (50, 9)), rng.uniform(0, 1, (50, 9)))
    batch = {"action": torch.rand(4, 16, 9), "ee_pose": torch.rand(4, 2, 9)}
    if kind == "rgbd":
        rgbd = torch.rand(4, 2, 2, 4, 48, 64)
        rgbd[..., 3, :, :] *= 1.5  # depth in metres
        batch["rgbd"] = rgbd.half()
    loss = policy.compute_loss(batch)
    loss.backward()
    assert torch.isfinite(loss)
    if kind == "rgbd":
        assert policy.obs_encoder.stem[0].weight.grad.abs().sum() > 0
    policy.eval()
    single = {k: v[0].numpy() for k, v in batch.items() if k != "action"}
    assert policy.predict_action(single).shape == (12, 9)



def test_a_planted_pickle_as_last_pt_is_refused_on_resume_and_never_runs(demo_dataset, tmp_path, plant_pickle):
    config = _train_config(demo_dataset, tmp_path / "run")
    last = train_policy(config, max_steps=5, progress=False)["checkpoint"]
    marker = plant_pickle(last, last)
    with pytest.raises(InputError, match=f"refused checkpoint {last}"):
        train_policy(config, progress=False)
    assert not marker.exists()


def test_a_second_trainer_of_one_run_directory_is_refused_naming_the_first(demo_dataset, tmp_path, hold_directory):
    run = tmp_path / "run"
    run.mkdir()
    holder = hold_directory(run, "train policy")
    with pytest.raises(StorageError, match=rf"is being written by `grits-lab train policy` \(pid {holder.pid} on"):
        train_policy(_train_config(demo_dataset, run), max_steps=2, progress=False)
    assert [p.name for p in run.iterdir()] == [".grits-lab.lock"]
