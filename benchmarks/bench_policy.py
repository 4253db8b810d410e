"""Benchmark of the diffusion policy: training steps/s, plan latency (batch 1 and 32), guided/unguided ratio.

Prints one JSON object. The guided plan uses the real spillage predictor network (untrained
weights; the cost does not depend on them) with its cloud embedding computed once per plan,
as the evaluation does; guidance is the paper's (rho 2.5, s 30 -> 6 of 16 steps guided).

    python benchmarks/bench_policy.py                      # cpu preset
    python benchmarks/bench_policy.py --preset paper       # needs a GPU to be practical
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time

import numpy as np
import torch

from grits_lab.policies.diffusion import DiffusionPolicy
from grits_lab.policies.diffusion.training_diffusion import load_train_config
from grits_lab.sampling import DDIMSampler, GuidanceConfig
from grits_lab.training import resolve_device, set_torch_threads


def fake_obs(policy: DiffusionPolicy, batch: int, n_points: int, device: torch.device, rng: np.random.Generator) -> dict[str, torch.Tensor]:
    cfg = policy.config
    obs = {"ee_pose": torch.tensor(rng.uniform(-0.2, 0.5, (batch, cfg.n_obs_steps, 9)), dtype=torch.float32, device=device)}
    if cfg.obs_encoder.kind == "pointcloud":
        obs["cloud"] = torch.tensor(rng.uniform(-0.2, 0.5, (batch, cfg.n_obs_steps, 3, n_points, 3)), dtype=torch.float32, device=device)
    elif cfg.obs_encoder.kind == "rgbd":
        h, w = cfg.obs_encoder.image_size
        obs["rgbd"] = torch.randint(0, 255, (batch, cfg.n_obs_steps, cfg.obs_encoder.cameras, 4, h, w), dtype=torch.uint8, device=device)
    return obs


def timed(fn, repeats: int, device: torch.device) -> float:
    """Median wall time of `fn` in ms after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        if device.type == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        fn()
        if device.type == "cuda":
            torch.cuda.synchronize()
        times.append((time.perf_counter() - t0) * 1000)
    return statistics.median(times)


def make_objective(policy: DiffusionPolicy, cloud: torch.Tensor, device: torch.device):
    """P(spill) of the executed chunk from a predictor of the team's default size (cloud embedded once)."""
    from grits_lab.spillage.predictor_config import PredictorModelConfig
    from grits_lab.spillage.model import SpillagePredictor

    predictor = SpillagePredictor(PredictorModelConfig(n_action_steps=policy.config.n_action_steps)).to(device).eval()
    with torch.no_grad():
        embedding = predictor.encode_cloud(cloud)
    start, n = policy.config.action_start, policy.config.n_action_steps
    return lambda traj: predictor.spill_probability(traj[:, start : start + n], embedding)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--preset", default="cpu", choices=["cpu", "paper"])
    parser.add_argument("--device", default="auto")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (1 = one evaluation worker's share of 2 cores)")
    parser.add_argument("--points", type=int, default=3000, help="points per object in the observed cloud")
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--train-steps", type=int, default=20)
    args = parser.parse_args()
    set_torch_threads(args.threads)
    device = resolve_device(args.device)
    config = load_train_config(f"experiments/policy_{args.preset}.yaml")
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    policy = DiffusionPolicy(config.policy)
    policy.fit_normalizers(rng.uniform(-0.2, 0.5, (100, 9)), rng.uniform(-0.2, 0.5, (100, 9)), rng.uniform(-0.2, 0.5, (1000, 3)))
    policy.to(device)
    out: dict = {
        "preset": args.preset,
        "device": str(device),
        "device_name": torch.cuda.get_device_name(device) if device.type == "cuda" else platform.processor() or platform.machine(),
        "threads": torch.get_num_threads(),
        "parameters_M": round(sum(p.numel() for p in policy.parameters()) / 1e6, 3),
        "ddim_steps": config.policy.scheduler.num_inference_steps,
    }

    # training throughput at the preset's batch size
    policy.train()
    optimizer = torch.optim.AdamW(policy.parameters(), lr=config.lr)
    batch = fake_obs(policy, config.batch_size, config.cache_points_per_object, device, rng)
    batch["action"] = torch.tensor(rng.uniform(-0.2, 0.5, (config.batch_size, config.policy.horizon, 9)), dtype=torch.float32, device=device)

    def train_step():
        loss = policy.compute_loss(batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()

    step_ms = timed(train_step, args.train_steps, device)
    out["train_batch_size"] = config.batch_size
    out["train_steps_per_s"] = round(1000 / step_ms, 2)

    # planning latency, including the observation encoder
    policy.eval()
    for b in (1, 32):
        obs = fake_obs(policy, b, args.points, device, rng)
        gen = torch.Generator(device=device).manual_seed(0)
        out[f"plan_ms_batch{b}"] = round(timed(lambda: policy.plan(obs, generator=gen), args.repeats, device), 2)
        try:
            cloud = obs["cloud"][:, -1] if "cloud" in obs else torch.zeros(b, 3, args.points, 3, device=device)
            embed_ms = timed(lambda: make_objective(policy, cloud, device), args.repeats, device)
            out[f"predictor_embedding_ms_batch{b}"] = round(embed_ms, 2)
            objective = make_objective(policy, cloud, device)
            for mode in ("x0", "xt"):
                guided = DDIMSampler(policy.noise_scheduler, GuidanceConfig(rho=2.5, s=30, gradient=mode, diagnostics=False, compare_unguided=False))
                ms = timed(lambda: policy.plan(obs, sampler=guided, objective=objective, generator=gen), args.repeats, device)
                # the ratio counts the cloud embedding, which a guided plan computes once
                out[f"guided_{mode}_plan_ms_batch{b}"] = round(ms + embed_ms, 2)
                out[f"guided_{mode}_over_unguided_batch{b}"] = round((ms + embed_ms) / out[f"plan_ms_batch{b}"], 3)
        except ImportError as exc:
            out["guided_error"] = f"spillage predictor unavailable: {exc}"
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
