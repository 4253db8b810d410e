"""Sweep benchmark, JSON output: per-trial overhead of a GRITS sweep with a pool per trial (before) and one pool per sweep (now).

Both ways run the sweep's own loop (`grits_lab.tune.study.run_trials` on a journal file) on the
same trials: `--trials` trials of the same (rho 2.5, s 30) on the same `--episodes` validation
episodes (chocolate balls, low level, scoops cut at 60 actions), so the simulation work of every
trial is the same and what differs is what the sweep pays around it:

- `pool_per_trial`: each trial makes its own pool, as every sweep did before: Ray started, actors
  started, simulators built and checkpoints hashed and loaded, then Ray shut down.
- `pool_per_sweep`: `GritsEvaluator`, one pool for all trials, shut down once at the end.

A trial's wall time is measured between the ends of consecutive trials (the first from the call
of `run_trials`), so it holds Optuna's ask and tell and the journal writes too. Overhead = trial
wall time - the trial's simulation work, the episodes' in-worker times packed on the workers
(max(longest episode, sum / workers)). With one pool per sweep, the trials after the first have
warm workers, so their own episode times are the work and their overhead is what the sweep adds
around the episodes (dispatch, results, Optuna, journal). A pool per trial loads everything
inside its episodes, so its work is the warm time of the same episodes (each episode's median
over the warm trials); the first trial of the pool per sweep is measured the same way and holds
the one start-up. The pool per trial runs first (a Ray left running by the other would be
reused); the ratios are taken within this one run. Checkpoints: freshly initialised networks of the quickstart's sizes (the cpu
predictor, the cpu policy with the quickstart's two-level U-Net, down dims 32, 64), or
`--policy` / `--predictor` files.

Usage: python benchmarks/bench_sweep_pool.py [--trials 4] [--episodes 2] [--workers 2] [--policy P --predictor P]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import pandas as pd
import yaml
from bench_evaluation import write_cpu_checkpoints  # this script's folder is on sys.path when run as a script

RHO, S = 2.5, 30


def sweep_files(folder: Path, policy: Path, predictor: Path, args: argparse.Namespace) -> Path:
    """The evaluation config and the sweep file both ways run; returns the sweep file."""
    evaluation = {
        "run_id": "bench", "output_dir": str(folder / "unused"), "methods": ["grits"], "foods": ["chocolate_balls"],
        "levels": ["low"], "trials": 1, "checkpoints": {"policy": str(policy), "predictor": str(predictor)},
        "scoop": {"max_steps": 60}, "cloud": {"n_points": 256, "cad_surface_samples": 4000},
        "executor": {"backend": "ray", "workers": args.workers, "num_cpus": args.workers},
    }
    (folder / "evaluate.yaml").write_text(yaml.safe_dump(evaluation, sort_keys=False))
    sweep = {
        "study_name": "bench", "n_trials": args.trials, "evaluator": "grits", "output_dir": str(folder / "sweeps"),
        "rho": {"low": 0.05, "high": 4.0, "log": True}, "s": {"low": 0, "high": 90, "step": 6},
        "enqueue": [{"rho": RHO, "s": S}], "objective": {"mode": "multi"},
        "validation": {"foods": ["chocolate_balls"], "levels": ["low"], "trials": args.episodes, "seed": 7000},
        "evaluation": {"config": str(folder / "evaluate.yaml"), "method": "grits", "checkpoints": [str(policy), str(predictor)]},
    }
    (folder / "sweep.yaml").write_text(yaml.safe_dump(sweep, sort_keys=False))
    return folder / "sweep.yaml"


class PoolPerTrial:
    """The sweep's evaluator as it was: every trial runs `evaluate_guidance` with no pool, so it makes and closes its own."""

    label = "pool per trial"

    def __init__(self, config) -> None:
        from grits_lab.evaluation.evaluation_config import load_evaluation_config

        self._keys = config.episodes()
        self._evaluation = load_evaluation_config(config.evaluation.config, config.evaluation.overrides)

    def __call__(self, rho: float, s: int, run_id: str) -> pd.DataFrame:
        from grits_lab.evaluation.evaluation_run import evaluate_guidance

        return evaluate_guidance(self._evaluation, self._keys, rho=rho, s=s, method="grits", run_id=run_id)

    def close(self) -> None:
        pass


def run_mode(name: str, config, evaluator, folder: Path) -> dict[str, object]:
    """Run the study's trials (all at RHO, S) with `evaluator`; trial wall times, close time, episode times."""
    import ray

    from grits_lab.tune.storage import open_storage
    from grits_lab.tune.study import open_study, run_trials

    assert not ray.is_initialized(), "each way must start its own Ray"
    storage, _ = open_storage(str(folder / f"{name}.journal"), folder / "unused.journal")
    study = open_study(config, storage)
    for _ in range(config.n_trials - 1):  # the first is the enqueued default, at the same point
        study.enqueue_trial({"rho": RHO, "s": S}, skip_if_exists=False)
    ends: list[float] = []
    records_dir = folder / name
    start = time.perf_counter()
    try:
        run_trials(config, study, storage, evaluator, records_dir=records_dir, progress=False,
                   after_trial=lambda _study: ends.append(time.perf_counter()))
    finally:
        closing = time.perf_counter()
        evaluator.close()
        close_s = time.perf_counter() - closing
    walls = [b - a for a, b in zip([start] + ends[:-1], ends)]
    episodes = [pd.read_parquet(p) for p in sorted(records_dir.glob("trial_*.parquet"))]
    errors = sum(int((frame["error"] != "").sum()) for frame in episodes)
    return {"trial_wall_s": walls, "close_s": close_s, "episode_errors": errors,
            "episode_s": [dict(zip(frame["seed"].astype(int), frame["wall_time_s"].astype(float))) for frame in episodes]}


def _rounded(per_trial: list[dict[int, float]]) -> list[list[float]]:
    return [[round(v, 3) for _, v in sorted(times.items())] for times in per_trial]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=4, help="trials each way (at least 2)")
    parser.add_argument("--episodes", type=int, default=2, help="validation episodes per trial")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--policy", help="a policy checkpoint (default: freshly initialised, quickstart size)")
    parser.add_argument("--predictor", help="a predictor checkpoint (default: freshly initialised, cpu preset)")
    args = parser.parse_args()
    if args.trials < 2:
        parser.error("--trials must be at least 2 (the warm episode times come from the trials after the first)")
    if bool(args.policy) != bool(args.predictor):
        parser.error("give both --policy and --predictor, or neither")
    import optuna
    import ray
    import torch

    from grits_lab.tune.grits_binding import GritsEvaluator
    from grits_lab.tune.study_config import load_study_config

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    folder = Path(tempfile.mkdtemp(prefix="bench-sweep-pool-"))
    if args.policy:
        policy, predictor = Path(args.policy).resolve(), Path(args.predictor).resolve()
        source = "given files"
    else:
        policy, predictor = write_cpu_checkpoints(folder, unet={"down_dims": [32, 64]})
        source = "freshly initialised: cpu predictor, cpu policy with down_dims [32, 64] (the quickstart's)"
    config = load_study_config(sweep_files(folder, policy, predictor, args))
    load_before = os.getloadavg()
    before = run_mode("pool_per_trial", config, PoolPerTrial(config), folder)
    now = run_mode("pool_per_sweep", config, GritsEvaluator(config), folder)
    load_after = os.getloadavg()

    def packed(times: list[float]) -> float:
        return max(max(times), sum(times) / args.workers)

    seeds = sorted(now["episode_s"][0])
    warm = {seed: statistics.median(trial[seed] for trial in now["episode_s"][1:]) for seed in seeds}
    work_s = packed(list(warm.values()))
    before_over = [round(w - work_s, 3) for w in before["trial_wall_s"]]
    now_over = [round(now["trial_wall_s"][0] - work_s, 3)] + [
        round(w - packed(list(times.values())), 3) for w, times in zip(now["trial_wall_s"][1:], now["episode_s"][1:])]
    steady = statistics.mean(now_over[1:])
    amortized = (sum(now_over) + now["close_s"]) / len(now_over)
    out = {
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                    "torch": torch.__version__, "ray": ray.__version__,
                    "load_average_1min_before_after": [round(load_before[0], 2), round(load_after[0], 2)]},
        "setup": {"trials_each_way": args.trials, "episodes_per_trial": args.episodes, "workers": args.workers,
                  "rho": RHO, "s": S, "food": "chocolate_balls/low", "scoop_max_steps": 60, "checkpoints": source,
                  "policy_mb": round(policy.stat().st_size / 2**20, 2), "predictor_mb": round(predictor.stat().st_size / 2**20, 2)},
        "warm_episode_s": {str(k): round(v, 3) for k, v in warm.items()},
        "trial_work_s": round(work_s, 3),
        "pool_per_trial": {"trial_wall_s": [round(w, 3) for w in before["trial_wall_s"]], "overhead_s": before_over,
                           "episode_s_in_worker": _rounded(before["episode_s"]), "episode_errors": before["episode_errors"]},
        "pool_per_sweep": {"trial_wall_s": [round(w, 3) for w in now["trial_wall_s"]], "overhead_s": now_over,
                           "episode_s_in_worker": _rounded(now["episode_s"]), "close_s": round(now["close_s"], 3),
                           "episode_errors": now["episode_errors"]},
        "overhead_per_trial_before_s": round(statistics.mean(before_over), 3),
        "overhead_per_trial_now_s": round(steady, 3),
        "startup_now_s": now_over[0],
        "overhead_per_trial_now_amortized_s": round(amortized, 3),
        "ratio_overhead_before_over_now": round(statistics.mean(before_over) / steady, 2) if steady > 0 else None,
        "ratio_trial_wall_before_over_now": round(statistics.mean(before["trial_wall_s"]) / statistics.mean(now["trial_wall_s"][1:]), 2),
        "goal_overhead_per_trial_s": 2.0,
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
