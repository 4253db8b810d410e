"""Evaluation benchmarks, JSON output: guided vs unguided planning latency (ratio, same run) and episodes per minute.

1. Planning latency. One `DiffusionPolicy.plan` at batch 1 with the plain DDIM sampler and with
   GRITS guidance (rho 2.5, s 30: the last 6 of 16 DDIM steps, detached A_0|k gradient), the
   guided plan including everything an episode pays for per plan (building the objective, which
   encodes the cloud once, and the per-step diagnostics). Plans alternate between the two so
   that machine noise hits both alike; the ratio of medians is reported. Presets: `cpu`
   (experiments/policy_cpu.yaml + predictor_cpu.yaml) and `paper` (policy_paper.yaml, RGB-D
   ResNet-18 and the (512, 1024, 2048) U-Net, + predictor_paper.yaml, 3,000 points per object).
   Weights are freshly initialised: latency does not depend on their values.
2. Throughput. `grits-lab evaluate`'s code path with a Ray pool of `--workers` actors on
   `--episodes` episodes per method (dp and grits, cpu preset networks, chocolate balls at the low
   level, scoops cut at 60 actions): episodes per minute, wall clock including Ray start-up.

Usage: python benchmarks/bench_evaluation.py [--presets cpu paper] [--repeats 10] [--episodes 4] [--workers 2] [--threads 1]
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from grits_lab.config import config_from_dict, load_yaml


def _policy(preset: str, unet: dict | None = None):
    """A freshly initialised policy of the preset (`unet`: keys replacing the preset's U-Net settings)."""
    from grits_lab.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig
    from grits_lab.sim import SimConfig
    from grits_lab.sim.env import scene_geometry
    from grits_lab.sim.expert import expert_trajectory

    data = load_yaml(f"experiments/policy_{preset}.yaml")["policy"]
    if unet:
        data = {**data, "unet": {**data.get("unet", {}), **unet}}
    cfg = config_from_dict(DiffusionPolicyConfig, data, "policy")
    torch.manual_seed(0)
    policy = DiffusionPolicy(cfg).eval()
    sim = SimConfig()
    scene = scene_geometry(sim, np.array(sim.target_workspace_center))
    actions = np.concatenate([expert_trajectory(scene, np.random.default_rng(i)) for i in range(4)])
    policy.fit_normalizers(actions, actions, np.random.default_rng(0).normal([0.6, -0.1, 0.03], 0.05, (1000, 3)))
    return policy, np.array(scene.source_bowl_center), actions


def _predictor(preset: str, actions: np.ndarray, bowl: np.ndarray):
    from grits_lab.data.normalize import ActionNormalizer
    from grits_lab.spillage import CloudNormalizer, PredictorConfig, SpillagePredictor, TrainedPredictor

    cfg = config_from_dict(PredictorConfig, load_yaml(f"experiments/predictor_{preset}.yaml"))
    torch.manual_seed(1)
    model = SpillagePredictor(cfg.model).eval().requires_grad_(False)
    return TrainedPredictor(model, ActionNormalizer().fit(actions), CloudNormalizer(centre=bowl), cfg), cfg


def _obs(policy, bowl: np.ndarray, points: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    cfg = policy.config
    pose = np.tile(np.array([0.6, -0.1, 0.12, 1, 0, 0, 0, 1, 0], np.float32), (cfg.n_obs_steps, 1))
    obs = {"ee_pose": pose}
    if cfg.obs_encoder.kind == "pointcloud":
        obs["cloud"] = rng.normal(bowl, 0.04, (cfg.n_obs_steps, 3, points, 3)).astype(np.float32)
    elif cfg.obs_encoder.kind == "rgbd":
        h, w = cfg.obs_encoder.image_size
        obs["rgbd"] = rng.uniform(0, 1, (cfg.n_obs_steps, cfg.obs_encoder.cameras, 4, h, w)).astype(np.float32)
    return obs


def bench_latency(preset: str, repeats: int) -> dict[str, object]:
    from grits_lab.sampling import DDIMSampler, GuidanceConfig
    from grits_lab.spillage import SpillageObjective

    policy, bowl, actions = _policy(preset)
    predictor, pcfg = _predictor(preset, actions, bowl)
    points = pcfg.data.points_per_object or 3000
    rng = np.random.default_rng(0)
    obs = _obs(policy, bowl, max(points, policy.config.obs_encoder.points_per_object), rng)
    cloud = rng.normal(bowl, 0.04, (3, points, 3)).astype(np.float32)
    guided_sampler = DDIMSampler(policy.noise_scheduler, GuidanceConfig(rho=2.5, s=30, gradient="x0", diagnostics=True, compare_unguided=False))
    cfg = policy.config

    def unguided() -> None:
        policy.plan(obs, generator=torch.Generator().manual_seed(0))

    def guided() -> None:
        objective = SpillageObjective(predictor, cloud, policy.action_normalizer, cfg.n_obs_steps, cfg.n_action_steps)
        policy.plan(obs, sampler=guided_sampler, objective=objective, generator=torch.Generator().manual_seed(0))

    unguided(), guided()  # warm-up
    times: dict[str, list[float]] = {"unguided": [], "guided": []}
    for _ in range(repeats):
        for name, fn in (("unguided", unguided), ("guided", guided)):
            t0 = time.perf_counter()
            fn()
            times[name].append((time.perf_counter() - t0) * 1e3)
    med = {k: statistics.median(v) for k, v in times.items()}
    return {
        "preset": preset,
        "policy_parameters": sum(p.numel() for p in policy.parameters()),
        "obs_encoder": cfg.obs_encoder.kind,
        "predictor_points_per_object": points,
        "ddim_steps": cfg.scheduler.num_inference_steps,
        "guided_steps": len(guided_sampler.guided_timesteps()),
        "unguided_median_ms": med["unguided"],
        "guided_median_ms": med["guided"],
        "unguided_min_ms": min(times["unguided"]),
        "guided_min_ms": min(times["guided"]),
        "ratio_guided_over_unguided": med["guided"] / med["unguided"],
        "target_ratio": 1.25,
        "repeats": repeats,
    }


def write_cpu_checkpoints(folder: Path, unet: dict | None = None) -> tuple[Path, Path]:
    """Freshly initialised cpu-preset policy and predictor checkpoints in `folder`: (policy.pt, predictor.pt)."""
    from grits_lab.spillage import save_predictor
    from grits_lab.training import save_checkpoint

    policy, bowl, actions = _policy("cpu", unet)
    save_checkpoint(folder / "policy.pt", {"policy": policy.policy_state()})
    predictor, pcfg = _predictor("cpu", actions, bowl)
    save_predictor(folder / "predictor.pt", config=pcfg, model=predictor.model, action_normalizer=predictor.action_normalizer,
                   cloud_normalizer=predictor.cloud_normalizer)
    return folder / "policy.pt", folder / "predictor.pt"


def bench_throughput(episodes: int, workers: int) -> dict[str, object]:
    from grits_lab.evaluation.evaluation_config import EvaluationConfig
    from grits_lab.evaluation.evaluation_run import evaluate

    tmp = Path(tempfile.mkdtemp(prefix="bench-eval-"))
    write_cpu_checkpoints(tmp)
    config = config_from_dict(EvaluationConfig, {
        "run_id": "bench", "output_dir": str(tmp / "run"), "methods": ["dp", "grits"], "foods": ["chocolate_balls"], "levels": ["low"],
        "trials": episodes, "checkpoints": {"policy": str(tmp / "policy.pt"), "predictor": str(tmp / "predictor.pt")},
        "scoop": {"max_steps": 60}, "cloud": {"n_points": 256, "cad_surface_samples": 4000},
        "executor": {"backend": "ray", "workers": workers, "num_cpus": workers},
    })
    t0 = time.perf_counter()
    records = evaluate(config, progress=False)
    wall = time.perf_counter() - t0
    return {
        "workers": workers,
        "episodes": int(len(records)),
        "errors": int((records["error"] != "").sum()),
        "wall_s_including_ray_startup": wall,
        "episodes_per_minute": 60.0 * len(records) / wall,
        "mean_episode_s_in_worker": float(records["wall_time_s"].mean()),
        "mean_scoop_steps": float(records["scoop_steps"].mean()),
        "food": "chocolate_balls/low", "methods": ["dp", "grits"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", nargs="+", default=["cpu", "paper"], choices=["cpu", "paper"])
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=4, help="episodes per method for the throughput run (0 skips it)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--threads", type=int, default=1, help="torch threads for the latency runs")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    out: dict[str, object] = {"machine": {"platform": platform.platform(), "processor": platform.processor(), "torch_threads": args.threads,
                                         "torch": torch.__version__}}
    out["latency"] = [bench_latency(p, args.repeats if p == "cpu" else max(2, args.repeats // 4)) for p in args.presets]
    if args.episodes > 0:
        out["throughput"] = bench_throughput(args.episodes, args.workers)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
