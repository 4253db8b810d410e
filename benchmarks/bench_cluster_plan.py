"""The paper-size study planned from measured costs: its wall time on 16, 64 and 256 cores, and where it stops scaling.

Four parts, each measured or read from committed records, then one plan built from them. Prints
one JSON object's plan and writes the whole object to `--output` (default
benchmarks/results/cluster_plan.json) and its tables beside it (cluster_plan.md):

1. `recorded_episodes`: wall seconds per evaluation episode inside a worker (one worker per core),
   per method and quantity level (brim included) and per food and level, read from every committed
   `episodes.csv` (studies/*/summaries/*, docs/archive/*; column `wall_time_s`).
2. `fresh`: measured now, on this machine: one evaluation episode per level (low, high: the brim
   level is a study's override, its cost is in the records) of the scripted expert and the rule-based method (`grits-lab evaluate --serial`, CPU seconds of that
   process from getrusage, start-up included); `--spillage-trials` spillage candidate trials of
   `--spillage-config` in this process (CPU seconds each, `time.process_time`); policy training
   steps/s of the cpu and paper presets (`bench_policy.py`, one thread).
3. `ray_overhead`: a local Ray of its own (own temp dir; Ray picks free ports) with `num_cpus` =
   each of `--workers` logical CPUs, the project's `RayExecutor` running `--tasks-per-worker` x
   workers probe episodes that sleep `--task-s` s (`grits_lab.runners.work.probe_episode`): pool
   start-up, makespan minus the ideal (tasks / workers x task_s), dispatch overhead per task
   ((workers x makespan - time inside the tasks) / tasks) and the driver's CPU seconds per task.
   Before each count, the memory available (/proc/meminfo) must hold that many workers at the
   memory per worker that the smallest count's pool took (available before minus after its
   start-up) plus `--reserve-gb`; otherwise it runs at the
   largest count that fits and says so (`capped_from`).
4. `plan`: the paper-size study (`--spillage-trials-total` spillage trials, `--demos` demos,
   `--eval-episodes` evaluation episodes over the paper's 8 methods, a `--sweep-trials` x
   `--sweep-episodes` sweep, policy training) on each of `--cores`: parallel stages take
   ceil(episodes / cores) rounds of the per-episode cost plus the measured dispatch overhead, or
   the driver's serial time (episodes x its CPU per task) when that is longer; training is serial.

Usage: nice -n 10 python benchmarks/bench_cluster_plan.py [--workers 16 64 256] [--task-s 2]
       [--skip-fresh] [--skip-ray]   (about 20 minutes on 2 shared cores)
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PAPER_METHODS = ["rule_based", "bc", "scone", "dp", "dp_post", "grits", "grits_raw", "grits_pointnet2"]
# Methods without committed records cost as the recorded method that plans the same way.
STAND_IN = {"bc": "dp", "scone": "dp_post", "grits_raw": "grits", "grits_pointnet2": "grits"}


def recorded_episodes() -> dict:
    """Per-episode wall seconds in a worker from every committed episodes.csv."""
    import pandas as pd

    files = sorted(glob.glob(str(ROOT / "studies/*/summaries/*/episodes.csv")) + glob.glob(str(ROOT / "docs/archive/*/episodes.csv")))
    frames = [pd.read_csv(f, usecols=lambda c: c in ("method", "food", "level", "wall_time_s")).assign(source=os.path.relpath(f, ROOT)) for f in files]
    data = pd.concat(frames).dropna(subset=["wall_time_s"])

    def table(keys: list[str]) -> dict:
        g = data.groupby(keys).wall_time_s
        out = {}
        for key, n, mean, median in zip(g.groups.keys(), g.count(), g.mean(), g.median()):
            out["/".join(key)] = {"episodes": int(n), "mean_s": round(float(mean), 2), "median_s": round(float(median), 2)}
        return out

    return {"files": [os.path.relpath(f, ROOT) for f in files], "episodes": int(len(data)),
            "by_method_level": table(["method", "level"]), "by_food_level": table(["food", "level"]),
            "by_level": {lvl: round(float(v), 2) for lvl, v in data.groupby("level").wall_time_s.mean().items()}}


def fresh_evaluation(food: str, methods: list[str]) -> dict:
    """One episode per level and method, `grits-lab evaluate --serial`, CPU of that process."""
    import pandas as pd
    import yaml

    with tempfile.TemporaryDirectory(prefix="cluster_plan_") as tmp:
        override = Path(tmp) / "override.yaml"
        override.write_text(yaml.safe_dump({"foods": [food], "levels": ["low", "high"], "trials": 1}))
        out = Path(tmp) / "run"
        command = [sys.executable, "-m", "grits_lab.cli", "evaluate", "experiments/evaluate_cpu.yaml", "--serial", "--no-progress",
                   "--methods", *methods, "--override", str(override), "--output-dir", str(out)]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        records = pd.read_parquet(out / "episodes.parquet") if (out / "episodes.parquet").exists() else None
    if records is None or proc.returncode not in (0, 1):
        return {"status": "failed", "returncode": proc.returncode, "error": "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-5:])}
    episodes = {f"{r.method}/{r.level}": round(float(r.wall_time_s), 2) for r in records.itertuples()}
    work = float(records.wall_time_s.sum())
    return {"status": "ok", "food": food, "episodes": episodes, "process_cpu_s": round(cpu, 1), "process_wall_s": round(wall, 1),
            "episode_wall_s_summed": round(work, 1),
            # the process's CPU share while it ran, applied to the episodes: CPU s per episode
            "cpu_s_per_episode": round(cpu / wall * work / len(records), 2), "start_up_wall_s": round(wall - work, 1)}


def fresh_spillage(config_path: str, trials: int) -> dict:
    """CPU seconds of `trials` spillage candidate trials, run in this process (clouds included)."""
    from grits_lab.collection.jobs import base_trajectory, load_collect_config
    from grits_lab.collection.spillage_trials import make_trial_spec, source_bowl_region
    from grits_lab.runners.work import WorkerContext, execute_spec

    config = load_collect_config(config_path)
    base, bowl = base_trajectory(config), source_bowl_region(config)
    ctx = WorkerContext(0)
    cpu, wall = [], []
    for index in range(trials):
        spec = make_trial_spec(config, base, bowl, "sphere", index)
        c0, w0 = time.process_time(), time.perf_counter()
        result = execute_spec(spec, ctx)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
        if not result.ok:
            return {"status": "failed", "config": config_path, "error": result.error}
    ctx.close()
    # the first trial builds the world; the rest reuse it, as a worker does
    steady = cpu[1:] or cpu
    return {"status": "ok", "config": config_path, "trials": trials, "cpu_s": [round(c, 2) for c in cpu],
            "wall_s": [round(w, 2) for w in wall], "cpu_s_per_trial": round(sum(steady) / len(steady), 2)}


def load_policy_max_steps(preset: str) -> int:
    from grits_lab.config import load_yaml

    return int(load_yaml(str(ROOT / f"experiments/policy_{preset}.yaml"))["max_steps"])


def fresh_training(preset: str, steps: int, timeout_s: float) -> dict:
    """Policy training steps/s of a preset on one thread (bench_policy.py)."""
    command = [sys.executable, str(HERE / "bench_policy.py"), "--preset", preset, "--repeats", "1", "--train-steps", str(steps), "--threads", "1"]
    try:
        proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return {"status": "timeout", "preset": preset, "timeout_s": timeout_s}
    if proc.returncode != 0:
        return {"status": "failed", "error": "\n".join((proc.stderr or proc.stdout).strip().splitlines()[-3:])}
    result = json.loads(proc.stdout[proc.stdout.index("{"):])
    max_steps = load_policy_max_steps(preset)
    return {"status": "ok", "preset": preset, "train_steps_per_s": result["train_steps_per_s"], "max_steps": max_steps,
            "parameters_M": result["parameters_M"], "training_s": round(max_steps / result["train_steps_per_s"], 1)}


def available_gb() -> float:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) / 1024**2
    return 0.0


def ray_overhead(workers: int, task_s: float, tasks_per_worker: int) -> dict:
    """Makespan, dispatch overhead and the driver's CPU per task for `workers` sleeping probe tasks."""
    import logging

    import ray

    from grits_lab.runners.ray_executor import RayExecutor
    from grits_lab.runners.spec import EpisodeSpec
    from grits_lab.runners.work import probe_episode

    tmp = tempfile.mkdtemp(prefix="gl_cp_", dir="/tmp")  # short: Ray's socket paths must fit 107 characters
    free_before = available_gb()
    t0 = time.perf_counter()
    ray.init(address="local", num_cpus=workers, include_dashboard=False, logging_level=logging.WARNING, _temp_dir=tmp)
    try:
        with RayExecutor(workers=workers, startup_timeout_s=1800) as ex:
            start_up = time.perf_counter() - t0
            rss = ex.worker_peak_rss_mb()
            pool_gb = free_before - available_gb()  # what the pool took from the machine (RSS counts shared pages)
            n = workers * tasks_per_worker
            specs = [EpisodeSpec(episode_id=f"t{i:05d}", work=probe_episode, seed=i, params={"sleep_s": task_s}) for i in range(n)]
            list(ex.map_unordered(specs[:workers]))  # warm-up: every actor has run once
            c0, w0 = time.process_time(), time.perf_counter()
            results = list(ex.map_unordered(specs))
            makespan = time.perf_counter() - w0
            driver_cpu = time.process_time() - c0
    finally:
        ray.shutdown()
        shutil.rmtree(tmp, ignore_errors=True)
    inside = sum(r.wall_time_s for r in results)
    ideal = tasks_per_worker * task_s
    return {"workers": workers, "tasks": n, "task_s": task_s, "ok": sum(r.ok for r in results),
            "pool_start_up_s": round(start_up, 1), "makespan_s": round(makespan, 2), "ideal_s": ideal,
            "makespan_minus_ideal_s": round(makespan - ideal, 2),
            "dispatch_overhead_per_task_s": round((workers * makespan - inside) / n, 4),
            "driver_cpu_per_task_s": round(driver_cpu / n, 5),
            "worker_rss_mb_median": round(sorted(rss)[len(rss) // 2], 1),
            "memory_taken_per_worker_mb": round(pool_gb * 1024 / workers, 1)}


def _pick(rows: list[dict], cores: int) -> dict:
    """The overhead row measured at the worker count nearest `cores` (log scale)."""
    return min(rows, key=lambda r: abs(math.log(r["workers"]) - math.log(cores)))


def parallel_stage(n: int, cost_s: float, cores: int, overhead: dict) -> dict:
    rounds = math.ceil(n / cores)
    workers_s = rounds * (cost_s + max(0.0, overhead["dispatch_overhead_per_task_s"]))
    driver_s = n * overhead["driver_cpu_per_task_s"]
    return {"episodes": n, "rounds": rounds, "wall_s": round(max(workers_s, driver_s) + overhead["pool_start_up_s"], 1),
            "limited_by": "driver" if driver_s > workers_s else ("episodes" if n <= cores else "cores")}


def plan(args: argparse.Namespace, report: dict) -> dict:
    rec = report["recorded_episodes"]["by_method_level"]
    fresh = report.get("fresh", {})
    levels = ["low", "high"]  # the paper's evaluation levels

    def method_cost(method: str) -> tuple[float, str]:
        source = method if any(k.startswith(method + "/") for k in rec) else STAND_IN.get(method, method)
        values = [rec[f"{source}/{lvl}"]["mean_s"] for lvl in levels if f"{source}/{lvl}" in rec]
        if not values and fresh.get("evaluation", {}).get("status") == "ok":
            values = [v for k, v in fresh["evaluation"]["episodes"].items() if k.split("/")[0] == source and k.split("/")[1] in levels]
        return (sum(values) / len(values) if values else float("nan")), source

    costs = {m: method_cost(m) for m in PAPER_METHODS}
    known = [c for c, _ in costs.values() if c == c]  # a method with neither records nor a fresh episode is left out
    eval_cost = sum(known) / len(known)
    evaluation = fresh.get("evaluation", {})
    expert = [v for k, v in evaluation.get("episodes", {}).items() if k.startswith("expert/")]
    demo_cost = sum(expert) / len(expert) if expert else float("nan")
    spill_cost = fresh.get("spillage", {}).get("cpu_s_per_trial", float("nan"))
    training = {p: fresh.get(f"training_{p}", {}) for p in ("cpu", "paper")}
    train_s = training["cpu"].get("training_s") or float("nan")
    rows = report["ray_overhead"]
    table = {}
    for cores in args.cores:
        over = _pick(rows, cores)
        stages = {
            "demos": parallel_stage(args.demos, demo_cost, cores, over),
            "spillage": parallel_stage(args.spillage_trials_total, spill_cost, cores, over),
            "evaluation": parallel_stage(args.eval_episodes, eval_cost, cores, over),
        }
        # a sweep trial's episodes run in parallel; several sweep processes share one storage
        per_trial = min(cores, args.sweep_episodes)
        processes = max(1, cores // args.sweep_episodes)
        # each sweep process keeps one pool of per_trial workers for all its trials (bench_sweep_pool.py)
        small = _pick(rows, per_trial)
        trial = parallel_stage(args.sweep_episodes, costs["grits"][0], per_trial, small)
        rounds = math.ceil(args.sweep_trials / processes)
        stages["sweep"] = {"trials": args.sweep_trials, "sweep_processes": processes, "rounds": rounds,
                           "wall_s": round(rounds * (trial["wall_s"] - small["pool_start_up_s"]) + small["pool_start_up_s"], 1),
                           "limited_by": "trials" if processes >= args.sweep_trials else "cores"}
        stages["policy_training"] = {"wall_s": train_s, "limited_by": "serial, cpu preset"}
        simulated = sum(s["wall_s"] for k, s in stages.items() if k != "policy_training")
        table[str(cores)] = {"stages": stages, "simulation_wall_s": round(simulated, 1),
                             "total_wall_s": round(simulated + train_s, 1), "overhead_row_workers": over["workers"]}
    # the driver keeps up while workers x its CPU per task < one episode's cost
    driver_limit = {str(r["workers"]): round(eval_cost / r["driver_cpu_per_task_s"]) if r["driver_cpu_per_task_s"] > 0 and eval_cost == eval_cost else None for r in rows}
    return {"per_episode_cost_s": {"evaluation_mean_over_8_methods": round(eval_cost, 2),
                                   "by_method": {m: {"s": round(c, 2), "from": s} for m, (c, s) in costs.items()},
                                   "demo (scripted expert, fresh)": round(demo_cost, 2), "spillage_trial (fresh)": spill_cost},
            "policy_training_s": {p: t.get("training_s") for p, t in training.items()},
            # a preset whose steps outlast the measurement's timeout: each step took longer than timeout / (steps + warm-up)
            "policy_training_s_at_least": {p: round(int(load_policy_max_steps(p)) * t["timeout_s"] / (args.train_steps + 1))
                                           for p, t in training.items() if t.get("status") == "timeout"},
            # past this many cores a stage runs in one round: more cores no longer shorten it
            "one_round_at_cores": {"demos": args.demos, "spillage": args.spillage_trials_total, "evaluation": args.eval_episodes,
                                   "sweep": args.sweep_trials * args.sweep_episodes},
            "by_cores": table, "workers_one_driver_keeps_busy": driver_limit}


def _hours(seconds: float | None) -> str:
    return "n/a" if seconds is None or seconds != seconds else f"{seconds / 3600:.2f}"


def _share(report: dict) -> str:
    ev = report.get("fresh", {}).get("evaluation", {})
    return f"{ev['process_cpu_s'] / ev['process_wall_s']:.0%}" if ev.get("status") == "ok" else "n/a"


def markdown(report: dict) -> str:
    """The plan and its measurements as a page (benchmarks/results/cluster_plan.md)."""
    plan, m = report["plan"], report["machine"]
    stages = ["demos", "spillage", "evaluation", "sweep", "policy_training"]
    lines = ["# The paper-size study on a cluster, planned from measured costs", "",
             f"Made by `benchmarks/bench_cluster_plan.py` on {report['date']}: {m['cpus']} CPUs, {m['platform']}, "
             f"load average {m['load_average_1min_at_start']} at the start. Every figure is in "
             "[cluster_plan.json](cluster_plan.json); the method is in the script's docstring.", "",
             "Wall time in hours per stage (and what limits it):", "",
             "| cores | " + " | ".join(stages) + " | total |", "|---:|" + "---|" * (len(stages) + 1)]
    for cores, row in plan["by_cores"].items():
        cells = [f"{_hours(row['stages'][s]['wall_s'])} ({row['stages'][s]['limited_by']})" for s in stages]
        lines.append(f"| {cores} | " + " | ".join(cells) + f" | {_hours(row['total_wall_s'])} |")
    cost = plan["per_episode_cost_s"]
    lines += ["", "Per-episode cost (s): evaluation mean over the 8 methods "
              f"{cost['evaluation_mean_over_8_methods']}, demo {cost['demo (scripted expert, fresh)']}, "
              f"spillage trial {cost['spillage_trial (fresh)']}; policy training (s, one CPU thread): "
              + ", ".join(f"{p} preset {t}" for p, t in plan["policy_training_s"].items() if t)
              + "".join(f"; {p} preset at least {t} (its steps outlasted the measurement)" for p, t in plan["policy_training_s_at_least"].items())
              + ". A stage runs in one round from as many cores as it has episodes: "
              + ", ".join(f"{k} {n}" for k, n in plan["one_round_at_cores"].items()) + ".", "",
              "Episode costs are wall seconds inside a worker, recorded or fresh, on this shared machine: upper "
              "bounds of a dedicated core's time (the fresh evaluation's process ran "
              f"{_share(report)} of its wall time on a CPU).", "",
              "Ray and the driver, probe tasks of known duration:", "",
              "| workers | pool start-up (s) | makespan - ideal (s) | dispatch overhead per task (s) | driver CPU per task (s) | memory per worker (MB) |",
              "|---:|---:|---:|---:|---:|---:|"]
    for r in report["ray_overhead"]:
        asked = f" (asked {r['capped_from']})" if "capped_from" in r else ""
        lines.append(f"| {r['workers']}{asked} | {r['pool_start_up_s']} | {r['makespan_minus_ideal_s']} | "
                     f"{r['dispatch_overhead_per_task_s']} | {r['driver_cpu_per_task_s']} | {r['memory_taken_per_worker_mb']} |")
    lines += ["", "Workers one driver keeps busy (one episode's cost / the driver's CPU per task), by the worker count measured: "
              + ", ".join(f"{w}: {n}" for w, n in plan["workers_one_driver_keeps_busy"].items()) + "."]
    lines += [f"- {note}" for note in report.get("ray_notes", [])]
    lines += ["", "Not measured here: " + "; ".join(report["not_measured"]) + "."]
    return "\n".join(lines) + "\n"


NOT_MEASURED = [
    "predictor training (no preset's training time is in a committed record; the plan leaves it out)",
    "how many candidate trials the balanced 4,000-trial dataset runs beyond 4,000 (each costs a trial)",
    "training on a GPU, and the paper-size networks' planning cost inside episodes (the recorded episodes use the cpu presets)",
    "network and object-store costs between nodes (one machine: every worker is local)",
    "bc, scone, grits_raw and grits_pointnet2 episodes (no records: costed as the method named in by_method's `from`)",
]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[16, 64, 256], help="Ray worker counts (logical CPUs) to measure")
    parser.add_argument("--task-s", type=float, default=2.0, help="seconds each probe task sleeps")
    parser.add_argument("--tasks-per-worker", type=int, default=4)
    parser.add_argument("--reserve-gb", type=float, default=4.0, help="memory left to the rest of the machine")
    parser.add_argument("--food", default="penne", help="food of the fresh evaluation episodes")
    parser.add_argument("--spillage-config", default="experiments/spillage.yaml")
    parser.add_argument("--spillage-trials", type=int, default=3)
    parser.add_argument("--train-steps", type=int, default=3)
    parser.add_argument("--train-timeout", type=float, default=300, help="seconds per preset's training measurement")
    parser.add_argument("--cores", type=int, nargs="+", default=[16, 64, 256])
    parser.add_argument("--spillage-trials-total", type=int, default=4000)
    parser.add_argument("--demos", type=int, default=80)
    parser.add_argument("--eval-episodes", type=int, default=800)
    parser.add_argument("--sweep-trials", type=int, default=30)
    parser.add_argument("--sweep-episodes", type=int, default=20)
    parser.add_argument("--skip-fresh", action="store_true", help="keep the fresh part of an existing --output")
    parser.add_argument("--skip-ray", action="store_true", help="keep the Ray part of an existing --output")
    parser.add_argument("--output", default=str(HERE / "results" / "cluster_plan.json"))
    args = parser.parse_args()
    output = Path(args.output)
    old = json.loads(output.read_text()) if output.exists() else {}
    if (args.skip_fresh and not old.get("fresh")) or (args.skip_ray and not old.get("ray_overhead")):
        print(f"{output}: no earlier fresh or ray_overhead part to keep; run without --skip-*", file=sys.stderr)
        return 2

    report: dict = {"date": time.strftime("%Y-%m-%d %H:%M:%S%z"),
                    "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                                "load_average_1min_at_start": round(os.getloadavg()[0], 2), "memory_available_gb_at_start": round(available_gb(), 1)},
                    "recorded_episodes": recorded_episodes()}
    if args.skip_fresh and args.skip_ray:  # a re-rendered plan keeps the date and machine of its measurements
        report["date"], report["machine"] = old.get("date", report["date"]), old.get("machine", report["machine"])
    if args.skip_fresh:
        report["fresh"] = old["fresh"]
    else:
        print("fresh: evaluation episodes", file=sys.stderr, flush=True)
        report["fresh"] = {"evaluation": fresh_evaluation(args.food, ["expert", "rule_based"])}
        print("fresh: spillage trials", file=sys.stderr, flush=True)
        report["fresh"]["spillage"] = fresh_spillage(args.spillage_config, args.spillage_trials)
        for preset in ("cpu", "paper"):
            print(f"fresh: policy training, {preset} preset", file=sys.stderr, flush=True)
            report["fresh"][f"training_{preset}"] = fresh_training(preset, args.train_steps, args.train_timeout)
    from grits_lab.io import write_text_atomic

    output.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(output, json.dumps({**old, **report}, indent=2, default=str) + "\n")  # kept if a later part fails
    if args.skip_ray:
        report["ray_overhead"], report["ray_notes"] = old["ray_overhead"], old.get("ray_notes", [])
    else:
        rows, notes, rss_gb = [], [], None
        for workers in sorted(args.workers):
            asked = workers
            if rss_gb is not None:
                fit = int((available_gb() - args.reserve_gb) / rss_gb)
                if fit < workers:
                    workers = max(1, fit)
                    notes.append(f"{asked} workers do not fit: {available_gb():.1f} GB available, {rss_gb * 1024:.0f} MB per worker, "
                                 f"{args.reserve_gb:g} GB kept free; measured at {workers}")
            print(f"ray: {workers} workers", file=sys.stderr, flush=True)
            row = ray_overhead(workers, args.task_s, args.tasks_per_worker)
            if workers != asked:
                row["capped_from"] = asked
            rss_gb = rss_gb or max(row["memory_taken_per_worker_mb"], 1.0) / 1024
            rows.append(row)
        report["ray_overhead"], report["ray_notes"] = rows, notes
    write_text_atomic(output, json.dumps(report, indent=2, default=str) + "\n")
    report["plan"] = plan(args, report)
    report["not_measured"] = NOT_MEASURED

    write_text_atomic(output, json.dumps(report, indent=2, default=str) + "\n")
    write_text_atomic(output.with_suffix(".md"), markdown(report))
    print(json.dumps(report["plan"], indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
