"""Benchmark of data-parallel policy training: steps/s for processes x threads layouts, in one run.

Trains the cpu-preset diffusion policy with the real training loop (grits_lab/policies/
demo_training.py) for `--steps` steps on a demonstration dataset, once per layout (`2x1`: two
processes of one torch thread each), and prints one JSON object: steps/s of the loop, wall time
including process start-up, and the speed-up over the first layout.

    grits-lab collect experiments/demos_quick.yaml          # the dataset, if not there yet
    python benchmarks/bench_data_parallel.py --dataset results/datasets/demos_quick
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from grits_lab.config import config_from_dict, config_to_dict
from grits_lab.policies.diffusion.training_diffusion import PolicyTrainConfig, load_train_config, train_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--dataset", default="results/datasets/demos_quick", help="a demonstration dataset (grits-lab collect)")
    parser.add_argument("--config", default="experiments/policy_cpu.yaml")
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--layouts", nargs="+", default=["1x1", "1x2", "2x1"], help="PROCESSESxTHREADS per run")
    args = parser.parse_args()
    try:
        layouts = [tuple(int(v) for v in layout.split("x")) for layout in args.layouts]
    except ValueError:
        parser.error(f"--layouts takes PROCESSESxTHREADS values such as 2x1; got {args.layouts}")
    if not Path(args.dataset).is_dir():
        parser.error(f"--dataset {args.dataset} is not a directory; collect one with `grits-lab collect experiments/demos_quick.yaml`")
    base = config_to_dict(load_train_config(args.config))
    out: dict = {"config": args.config, "dataset": args.dataset, "steps": args.steps, "batch_size": base["batch_size"],
                 "cpu_count": os.cpu_count(), "runs": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for n, threads in layouts:
            raw = {**base, "dataset": args.dataset, "output_dir": str(Path(tmp) / f"{n}x{threads}"), "num_processes": n, "num_threads": threads,
                   "max_steps": args.steps, "val_every": 10 * args.steps, "checkpoint_every": 10 * args.steps}
            config = config_from_dict(PolicyTrainConfig, raw)
            started = time.perf_counter()
            summary = train_policy(config, progress=False)
            wall = time.perf_counter() - started
            out["runs"][f"{n}x{threads}"] = {"steps_per_s": round(summary["steps"] / summary["seconds"], 2), "wall_s": round(wall, 1),
                              "final_train_loss": round(summary["final_train_loss"], 4)}
    first = next(iter(out["runs"].values()))
    for run in out["runs"].values():
        run["speedup"] = round(run["steps_per_s"] / first["steps_per_s"], 2)
        run["wall_speedup"] = round(first["wall_s"] / run["wall_s"], 2)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
