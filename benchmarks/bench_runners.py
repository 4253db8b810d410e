"""Benchmark of the episode engine: episodes/min with 1 and 2 Ray workers, orchestration overhead, worker memory.

Runs one spillage candidate trial (real simulation, clouds included) repeatedly, three ways: bare (the work function
called in this process, no executor: the simulation time), with 1 Ray worker and with 2. Prints
one JSON object:

    episodes_per_min_bare, episodes_per_min_1, episodes_per_min_2, scaling_2_vs_1,
    overhead_1_worker = (wall with 1 worker - bare wall) / bare wall,
    engine_overhead_N = (N x job wall - time inside the work function) / that time, i.e. what the
        engine adds per episode (dispatch, result transfer, idle workers), independent of how fast
        the machine happens to be during the run,
    peak_rss_mb_per_worker, ...

Usage: python benchmarks/bench_runners.py [--episodes 8] [--config experiments/spillage_quick.yaml]
Ray start-up (about 3 s) and actor start-up are excluded: they are paid once per job, not per episode.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=8, help="episodes per measurement (even)")
    parser.add_argument("--config", default="experiments/spillage_quick.yaml")
    parser.add_argument("--shape", default="sphere", help="particle shape of the benchmark trial")
    parser.add_argument("--index", type=int, default=0, help="candidate index of the benchmark trial")
    args = parser.parse_args()

    import numpy as np
    import ray

    from grits_lab.collection.jobs import base_trajectory, load_collect_config
    from grits_lab.collection.spillage_trials import make_trial_spec, source_bowl_region
    from grits_lab.runners import SerialExecutor
    from grits_lab.runners.ray_executor import RayExecutor
    from grits_lab.runners.work import WorkerContext, execute_spec

    config = load_collect_config(args.config)
    base = base_trajectory(config)
    bowl = source_bowl_region(config)
    # One candidate trial repeated under distinct ids: every episode costs the same, so the 1 vs 2
    # worker ratio measures the engine's parallelism rather than the luck of the draw.
    one = make_trial_spec(config, base, bowl, args.shape, args.index)
    specs = [one.replace(episode_id=f"bench-{i:03d}") for i in range(args.episodes)]

    # Warm-up: imports and the first world build are paid once per worker, not per episode.
    ctx = WorkerContext(0)
    execute_spec(specs[0], ctx)
    t0 = time.perf_counter()
    bare = [execute_spec(s, ctx) for s in specs]
    bare_wall = time.perf_counter() - t0
    ctx.close()
    assert all(r.ok for r in bare), [r.error for r in bare if not r.ok]

    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="WARNING")
    out = {}
    for workers in (1, 2):
        with RayExecutor(workers=workers) as ex:
            list(ex.map_unordered([specs[0].replace(episode_id=f"warm{i}") for i in range(workers)]))
            t0 = time.perf_counter()
            results = list(ex.map_unordered(specs))
            out[workers] = time.perf_counter() - t0
            # Time spent inside the work function, measured in the worker: what remains of the
            # job's wall time (x workers) is dispatch, transfer and idle workers.
            out[f"work_{workers}"] = sum(r.wall_time_s for r in results)
            rss = ex.worker_peak_rss_mb()
        assert all(r.ok for r in results)
        same = {r.episode_id: r.payload["meta"]["label"] for r in results} == {r.episode_id: r.payload["meta"]["label"] for r in bare}
        out[f"same_{workers}"] = same
        out[f"rss_{workers}"] = rss
    ray.shutdown()
    n = len(specs)
    report = {
        "machine": f"{platform.node()} {os.cpu_count()} cores",
        "episodes": n,
        "config": args.config,
        "mean_episode_s_bare": round(bare_wall / n, 3),
        "episodes_per_min_bare": round(60 * n / bare_wall, 2),
        "episodes_per_min_1": round(60 * n / out[1], 2),
        "episodes_per_min_2": round(60 * n / out[2], 2),
        "scaling_2_vs_1": round(out[1] / out[2], 3),
        "overhead_1_worker": round((out[1] - bare_wall) / bare_wall, 4),
        "engine_overhead_1_worker": round((out[1] - out["work_1"]) / out["work_1"], 4),
        "engine_overhead_2_workers": round((2 * out[2] - out["work_2"]) / out["work_2"], 4),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "peak_rss_mb_per_worker": round(max(out["rss_1"] + out["rss_2"]), 1),
        "labels_match_bare": bool(out["same_1"] and out["same_2"]),
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
