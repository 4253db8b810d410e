"""Simulation speed on one core: per food and level, and the speed levers one by one with their effect on spills.

Table (default): for each food at the chosen quantity level(s) the benchmark builds and settles a
world (particles, settled fill height, build + settle time), then plays the nominal expert scoop
with camera rendering off and, optionally, on (both cameras every 10 Hz step). Real-time factor =
simulated seconds per CPU second of this process (the steadier measure on a shared machine; wall
figures are reported too).

Levers (`--levers`): one fixed set of shifted scoops (the spillage dataset's own perturbations of
the mean demonstration, +-7 cm X, +-5 cm Y and Z, followed by its level lift-and-exit) on full
bowls, played once with the defaults and once per lever changed alone: time step, solver
iterations, contact breaking threshold, freezing particles far from the spoon, coarse-graining.
Each lever reports its real-time factor relative to the defaults (a ratio taken in this run)
and the spill and scoop counts of the same trials, so a speed-up that changes what spills shows.

    python benchmarks/bench_sim.py                          # every food, high level, rendering off and on
    python benchmarks/bench_sim.py --level all --render off # every level
    python benchmarks/bench_sim.py --levers --lever-trials 4
Prints one JSON object (and, with --markdown, the tables as Markdown on stderr).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import replace

LEVER_FOODS = ("mung_beans", "soybeans", "brown_rice")


def _levels(food, which: str) -> list[str]:
    names = list(food.levels)
    return names if which == "all" else [{"low": names[0], "high": names[-1], "middle": names[len(names) // 2]}[which]]


def food_table(args) -> list[dict]:
    from grits_lab.sim import ScoopEnv
    from grits_lab.sim.playback import play_trajectory
    from grits_lab.sim.expert import nominal_expert_trajectory

    env = ScoopEnv()
    foods = env.foods.names() if args.foods == "all" else args.foods.split(",")
    modes = ["off", "on"] if args.render == "both" else [args.render]
    results = []
    for food in foods:
        for level in _levels(env.foods.get(food), args.level):
            for mode in modes:
                for r in range(args.repeats):
                    seed = args.seed + r
                    w0, c0 = time.perf_counter(), time.process_time()
                    env.reset(seed=seed, options={"food": food, "level": level})
                    build_wall, build_cpu = time.perf_counter() - w0, time.process_time() - c0
                    height = env.fill_height()
                    traj = nominal_expert_trajectory(env.scene(), env.config.control_hz)
                    on_step = (lambda t, e, obs: e.render_cameras()) if mode == "on" else None
                    w1, c1 = time.perf_counter(), time.process_time()
                    record = play_trajectory(env, traj, on_step=on_step)
                    run_wall, run_cpu = time.perf_counter() - w1, time.process_time() - c1
                    sim_s = record.n_steps / env.config.control_hz
                    results.append({
                        "food": food, "level": level, "render": mode, "seed": seed, "n_particles": record.n_particles,
                        "fill_height_cm": round(100 * height, 2),
                        "build_settle_wall_s": round(build_wall, 3), "build_settle_cpu_s": round(build_cpu, 3),
                        "settle_sim_s": round(env.world.settle_time_s, 3), "episode_sim_s": sim_s,
                        "sim_per_wall": round(sim_s / run_wall, 3), "sim_per_cpu": round(sim_s / run_cpu, 3),
                        "episodes_per_minute_wall": round(60.0 / (build_wall + run_wall), 2),
                        "episodes_per_minute_cpu": round(60.0 / (build_cpu + run_cpu), 2),
                        "scoop_success": record.scoop_success, "spilled": record.spilled, "scooped": record.scooped,
                    })
                    if os.environ.get("BENCH_VERBOSE"):
                        print(json.dumps(results[-1]), file=sys.stderr, flush=True)
    env.close()
    return results


def _lever_configs(default) -> dict[str, tuple]:
    """name -> (SimConfig, coarse-grain multiplier); each changes one thing against the defaults."""
    return {
        "defaults": (default, 1.0),
        "time_step 1/240 s": (replace(default, time_step=1.0 / 240.0), 1.0),
        "solver_iterations 10": (replace(default, solver_iterations=10), 1.0),
        "contact_breaking_threshold 2 mm": (replace(default, contact_breaking_threshold=0.002), 1.0),
        "freeze_distance 5 cm": (replace(default, freeze_distance=0.05), 1.0),
        "coarse_grain x0.8 (finer grains, ~2x particles)": (default, 0.8),
    }


def lever_runs(args) -> dict:
    """Play the fixed set of shifted scoops under each lever; per lever: CPU time, spills, scoops."""
    import numpy as np

    from grits_lab.collection.spillage_trials import SpillageConfig, expert_mean_trajectory, make_trial_spec, source_bowl_region
    from grits_lab.sim import ScoopEnv
    from grits_lab.sim.sim_config import SimConfig
    from grits_lab.sim.foods import load_foods

    config = SpillageConfig()
    base, bowl = expert_mean_trajectory(config), source_bowl_region(config)
    trajectories = [make_trial_spec(config, base, bowl, "sphere", k).trajectory for k in range(args.lever_trials)]
    library = load_foods()
    out = {}
    for name, (cfg, grain) in _lever_configs(SimConfig()).items():
        env = ScoopEnv(cfg)
        rows = []
        for food_name in LEVER_FOODS:
            food = library.get(food_name)
            if grain != 1.0:
                food = replace(food, components=[replace(c, coarse_grain=max(1.0, c.coarse_grain * grain)) for c in food.components])
            for k, traj in enumerate(trajectories):
                env.reset(seed=args.seed + k, options={"food_spec": food, "level": "high"})
                c0 = time.process_time()
                for action in traj:
                    env.step(np.asarray(action, dtype=np.float64))
                cpu = time.process_time() - c0
                m = env.metrics()
                rows.append({"food": food_name, "trial": k, "n_particles": m["n_particles"], "cpu_s": cpu,
                             "sim_s": len(traj) / cfg.control_hz, "spilled": m["spilled"], "scooped": m["scooped"]})
        env.close()
        sim_s, cpu_s = sum(r["sim_s"] for r in rows), sum(r["cpu_s"] for r in rows)
        out[name] = {
            "sim_per_cpu": round(sim_s / cpu_s, 3),
            "mean_particles": round(float(np.mean([r["n_particles"] for r in rows])), 1),
            "spilled": [r["spilled"] for r in rows],
            "scooped": [r["scooped"] for r in rows],
            "trials_with_spill": int(sum(r["spilled"] > 0 for r in rows)),
        }
        if os.environ.get("BENCH_VERBOSE"):
            print(name, json.dumps(out[name]), file=sys.stderr, flush=True)
    ref = out["defaults"]["sim_per_cpu"]
    for v in out.values():
        v["speed_vs_defaults"] = round(v["sim_per_cpu"] / ref, 3)
    return {"foods": list(LEVER_FOODS), "level": "high", "trials_per_food": args.lever_trials, "levers": out}


def markdown(table: list[dict], levers: dict | None) -> str:
    lines = []
    if table:
        lines += ["| food | level | particles | fill height (cm) | build + settle (CPU s) | real-time factor (render off) |",
                  "|---|---|---:|---:|---:|---:|"]
        for r in table:
            if r["render"] == "off":
                lines.append(f"| {r['food']} | {r['level']} | {r['n_particles']} | {r['fill_height_cm']:.1f} | "
                             f"{r['build_settle_cpu_s']:.2f} | {r['sim_per_cpu']:.2f} |")
    if levers:
        lines += ["", f"Levers: {', '.join(levers['foods'])} at {levers['level']}, {levers['trials_per_food']} shifted scoops each",
                  "", "| lever | real-time factor | vs defaults | trials with spill | spilled per trial | scooped per trial |",
                  "|---|---:|---:|---:|---|---|"]
        for name, v in levers["levers"].items():
            lines.append(f"| {name} | {v['sim_per_cpu']:.2f} | {v['speed_vs_defaults']:.2f} | {v['trials_with_spill']} | "
                         f"{v['spilled']} | {v['scooped']} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--foods", default="all", help="comma-separated food names, or 'all'")
    parser.add_argument("--level", default="high", choices=["low", "middle", "high", "all"], help="which quantity level(s) of each food")
    parser.add_argument("--render", default="both", choices=["off", "on", "both"])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--levers", action="store_true", help="measure the speed levers one by one instead of the food table")
    parser.add_argument("--lever-trials", type=int, default=4, help="shifted scoops per food in the lever runs")
    parser.add_argument("--markdown", action="store_true", help="also print the tables as Markdown on stderr")
    args = parser.parse_args()

    from grits_lab.sim.sim_config import SimConfig

    cfg = SimConfig()
    table = [] if args.levers else food_table(args)
    levers = lever_runs(args) if args.levers else None
    if args.markdown:
        print(markdown(table, levers), file=sys.stderr)
    print(json.dumps({
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "load_avg_1m": os.getloadavg()[0]},
        "physics": {"time_step": cfg.time_step, "solver_iterations": cfg.solver_iterations,
                    "contact_breaking_threshold": cfg.contact_breaking_threshold, "control_hz": cfg.control_hz},
        "results": table,
        **({"levers": levers} if levers else {}),
    }))


if __name__ == "__main__":
    main()
