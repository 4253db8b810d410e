"""Latency of the spillage predictor on CPU: forward and forward+backward at batch 1 and 32, JSON output.

Three backward variants are timed, because guidance and training need different ones:
- `train_fwd_bwd`: loss.backward() into every weight (a training step without the optimizer);
- `guide_fwd_bwd`: frozen weights, encode the cloud and take d P(spill) / d trajectory (one guided
  step when nothing is cached);
- `guide_traj_only`: d P(spill) / d trajectory from a cached cloud embedding (every guided step
  after the first: the cloud is encoded once per plan).

Usage: python benchmarks/bench_predictor.py [--points 3000] [--threads 2] [--repeats 20] [--encoders dp3 pointnet2]
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time

import torch

from grits_lab.spillage.predictor_config import PredictorModelConfig
from grits_lab.spillage.model import SpillagePredictor


def _time(fn, repeats: int, warmup: int = 3) -> dict[str, float]:
    for _ in range(warmup):
        fn()
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append((time.perf_counter() - t0) * 1e3)
    return {"median_ms": statistics.median(samples), "min_ms": min(samples), "max_ms": max(samples)}


def bench(encoder: str, batch: int, points: int, repeats: int) -> dict[str, object]:
    torch.manual_seed(0)
    model = SpillagePredictor(PredictorModelConfig(encoder=encoder))
    cloud = torch.randn(batch, 3, points, 3)
    traj = torch.rand(batch, 12, 9) * 2 - 1
    labels = torch.zeros(batch, dtype=torch.long)

    def forward():
        with torch.no_grad():
            model(traj, cloud)

    def train_fwd_bwd():
        model.zero_grad(set_to_none=True)
        torch.nn.functional.cross_entropy(model(traj, cloud), labels).backward()

    frozen = SpillagePredictor(PredictorModelConfig(encoder=encoder)).eval().requires_grad_(False)

    def guide_fwd_bwd():
        t = traj.clone().requires_grad_(True)
        emb = frozen.encode_cloud(cloud)
        torch.autograd.grad(frozen.spill_probability(t, emb).sum(), t)

    with torch.no_grad():
        cached = frozen.encode_cloud(cloud)

    def guide_traj_only():
        t = traj.clone().requires_grad_(True)
        torch.autograd.grad(frozen.spill_probability(t, cached).sum(), t)

    model.train()
    return {
        "encoder": encoder,
        "batch": batch,
        "points_per_object": points,
        "parameters": sum(p.numel() for p in model.parameters()),
        "forward": _time(forward, repeats),
        "train_fwd_bwd": _time(train_fwd_bwd, repeats),
        "guide_fwd_bwd": _time(guide_fwd_bwd, repeats),
        "guide_traj_only": _time(guide_traj_only, repeats),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=3000)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 32])
    parser.add_argument("--encoders", nargs="+", default=["dp3", "pointnet2"], choices=["dp3", "pointnet2"])
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    results = []
    for encoder in args.encoders:
        for batch in args.batches:
            # PointNet++ at batch 32 is slow on a CPU: fewer repeats keep the run short
            repeats = args.repeats if encoder == "dp3" or batch == 1 else max(3, args.repeats // 5)
            results.append(bench(encoder, batch, args.points, repeats))
    dp3_b1 = next((r for r in results if r["encoder"] == "dp3" and r["batch"] == 1), None)
    summary = {
        "machine": {"cpu_threads": args.threads, "torch": torch.__version__, "python": platform.python_version(), "processor": platform.processor() or platform.machine()},
        "target": "DP3 forward+backward at batch 1 <= 30 ms",
        "dp3_batch1_guide_fwd_bwd_ms": dp3_b1["guide_fwd_bwd"]["median_ms"] if dp3_b1 else None,
        "dp3_batch1_train_fwd_bwd_ms": dp3_b1["train_fwd_bwd"]["median_ms"] if dp3_b1 else None,
        "results": results,
    }
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
