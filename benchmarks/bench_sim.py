"""Simulation speed on one core: build + settle time, simulated seconds per wall second, episodes per minute.

For each food (at the chosen quantity level) the benchmark builds and settles a world, then plays
the expert scoop with camera rendering off and, optionally, on (both cameras every 10 Hz step).
Prints one JSON object. Wall and CPU (process) times are both reported: on a shared machine the
CPU time is the steadier measure of the simulator's own cost.

    python benchmarks/bench_sim.py                      # every food, its middle level, rendering off and on
    python benchmarks/bench_sim.py --foods mung_beans --render off --repeats 3
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--foods", default="all", help="comma-separated food names, or 'all'")
    parser.add_argument("--level", default="middle", choices=["low", "middle", "high"], help="which quantity level of each food")
    parser.add_argument("--render", default="both", choices=["off", "on", "both"])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    from grits_lab.seeding import derive_seed, make_rng
    from grits_lab.sim import ScoopEnv, expert_trajectory
    from grits_lab.sim.episode import play_trajectory

    env = ScoopEnv()
    foods = env.foods.names() if args.foods == "all" else args.foods.split(",")
    modes = ["off", "on"] if args.render == "both" else [args.render]
    results = []
    for food in foods:
        levels = list(env.foods.get(food).levels)
        level = {"low": levels[0], "high": levels[-1], "middle": levels[len(levels) // 2]}[args.level]
        for mode in modes:
            for r in range(args.repeats):
                seed = args.seed + r
                w0, c0 = time.perf_counter(), time.process_time()
                env.reset(seed=seed, options={"food": food, "level": level})
                build_wall, build_cpu = time.perf_counter() - w0, time.process_time() - c0
                traj = expert_trajectory(env.scene(), make_rng(derive_seed(seed, "expert")))
                on_step = (lambda t, e, obs: e.render_cameras()) if mode == "on" else None
                w1, c1 = time.perf_counter(), time.process_time()
                record = play_trajectory(env, traj, on_step=on_step)
                run_wall, run_cpu = time.perf_counter() - w1, time.process_time() - c1
                sim_s = record.n_steps / env.config.control_hz
                results.append({
                    "food": food, "level": level, "render": mode, "seed": seed, "n_particles": record.n_particles,
                    "build_settle_wall_s": round(build_wall, 3), "build_settle_cpu_s": round(build_cpu, 3),
                    "settle_sim_s": round(env.world.settle_time_s, 3), "episode_sim_s": sim_s,
                    "sim_per_wall": round(sim_s / run_wall, 3), "sim_per_cpu": round(sim_s / run_cpu, 3),
                    "episodes_per_minute_wall": round(60.0 / (build_wall + run_wall), 2),
                    "episodes_per_minute_cpu": round(60.0 / (build_cpu + run_cpu), 2),
                    "scoop_success": record.scoop_success, "spilled": record.spilled,
                })
                print(json.dumps(results[-1]), flush=True) if os.environ.get("BENCH_VERBOSE") else None
    env.close()
    print(json.dumps({
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "load_avg_1m": os.getloadavg()[0]},
        "physics": {"time_step": env.config.time_step, "solver_iterations": env.config.solver_iterations,
                    "control_hz": env.config.control_hz},
        "results": results,
    }))


if __name__ == "__main__":
    main()
