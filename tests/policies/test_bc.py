"""Behavior cloning trains on the diffusion policy's demonstration loop: learning, no EMA, exact resume."""

import pandas as pd
import torch

from grits_lab.config import config_from_dict
from grits_lab.policies.bc.training_bc import BCTrainConfig, train_bc

from tests.policies.test_diffusion_policy import TINY_POLICY

torch.set_num_threads(1)


def test_bc_shares_the_loop_resume_included(demo_dataset, tmp_path):
    def bc_config(out):
        return config_from_dict(BCTrainConfig, {
            "dataset": str(demo_dataset), "output_dir": str(out), "device": "cpu", "num_threads": 1, "batch_size": 16,
            "max_steps": 20, "lr": 1e-3, "warmup_steps": 5, "log_every": 5, "val_every": 10, "val_batches": 1,
            "checkpoint_every": 10, "cache_points_per_object": 32,
            "policy": {**{k: v for k, v in TINY_POLICY.items() if k != "unet"}, "hidden": [32], "dropout": 0.0},
        })

    straight = train_bc(bc_config(tmp_path / "a"), progress=False)
    train_bc(bc_config(tmp_path / "b"), max_steps=10, progress=False)
    resumed = train_bc(bc_config(tmp_path / "b"), progress=False)
    assert resumed["resumed_from"] == 10 and straight["final_train_loss"] < straight["first_loss"]
    # The policy's metric logger: one row per logged step, the curves drawn when training stops.
    log = pd.read_csv(tmp_path / "a" / "metrics.csv")
    assert list(log["step"]) == [5, 10, 15, 20] and log["val_loss"].notna().sum() == 2 and log["lr"].notna().all()
    assert (tmp_path / "a" / "curves.png").stat().st_size > 0
    sa = torch.load(straight["checkpoint"], weights_only=True)
    sb = torch.load(resumed["checkpoint"], weights_only=True)
    assert sa["ema"] is None  # BC is judged by its own weights
    for key, value in sa["policy"]["model"].items():
        torch.testing.assert_close(sb["policy"]["model"][key], value, rtol=1e-5, atol=1e-6)


def test_train_commands_run_both_policies_from_yaml(demo_dataset, tmp_path, capsys):
    import json

    import yaml

    from grits_lab.cli import main

    common = {"dataset": str(demo_dataset), "device": "cpu", "num_threads": 1, "batch_size": 8, "max_steps": 4,
              "warmup_steps": 1, "log_every": 2, "val_every": 2, "val_batches": 1, "checkpoint_every": 2, "cache_points_per_object": 32}
    configs = {
        "policy": {**common, "output_dir": str(tmp_path / "dp"), "policy": TINY_POLICY},
        "bc": {**common, "output_dir": str(tmp_path / "bc"),
               "policy": {**{k: v for k, v in TINY_POLICY.items() if k != "unet"}, "hidden": [16]}},
    }
    for name, raw in configs.items():
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(raw))
        assert main(["train", name, str(path), "--max-steps", "2", "--no-progress"]) == 0
        summary = json.loads(capsys.readouterr().out)
        assert summary["steps"] == 2 and (tmp_path / name.replace("policy", "dp") / "checkpoints" / "last.pt").exists()
        assert main(["train", name, str(path), "--max-steps", "0"]) == 2
        assert "--max-steps must be at least 1" in capsys.readouterr().err
