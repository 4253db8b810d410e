"""Evaluation-config builder shared by the evaluation tests."""

from __future__ import annotations
from pathlib import Path
from grits_lab.config import config_from_dict

N_POINTS = 32  # points per object in the tiny test clouds
# Record columns that measure time, which differ between otherwise identical runs.
TIMING = ["wall_time_s", "scoop_time_s", "transfer_time_s", "plan_time_mean_s", "plan_time_max_s"]


def eval_config(models: dict[str, str], tmp: Path, **changes):
    """A small evaluation config: a few-particle training food, short scoops, serial executor."""
    from grits_lab.evaluation.evaluation_config import EvaluationConfig

    data = {
        "run_id": "test", "output_dir": str(tmp), "seed": 3, "methods": ["dp"], "foods": ["chocolate_balls"], "levels": ["low"],
        "trials": 1, "checkpoints": {"policy": models["policy"], "predictor": models["predictor"], "predictor_raw": models["predictor"],
                                      "predictor_pointnet2": models["predictor"], "predictor_horizon": models["predictor"],
                                      "bc": models["bc"], "demos": models["demos"]},
        "scoop": {"max_steps": 36, "min_steps": 12}, "transfer": {"pour_steps": 8, "settle_steps": 5},
        "cloud": {"n_points": N_POINTS, "cad_surface_samples": 400}, "executor": {"backend": "serial"},
    }
    for key, value in changes.items():
        data[key] = {**data[key], **value} if isinstance(value, dict) and isinstance(data.get(key), dict) else value
    return config_from_dict(EvaluationConfig, data)
