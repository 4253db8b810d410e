"""`grits-lab rollout`, `grits-lab scene` and `grits-lab foods`: the simulated world from the command line."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from grits_lab.errors import InputError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("rollout", help="play a trajectory (or the scripted expert) and print the episode record")
    p.add_argument("--food", required=True, help="food name (see `grits-lab foods`)")
    p.add_argument("--quantity", required=True, help="quantity level of that food, e.g. low / medium / high")
    p.add_argument("--seed", type=int, required=True, help="episode seed (world, particles, target bowl, expert)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--trajectory", help="(T, 9) xyz + 6-D rotation or (T, 7) xyz + quaternion xyzw .npy, 10 Hz, world frame")
    src.add_argument("--expert", action="store_true", help="play the seeded, randomized scripted expert scoop")
    p.add_argument("--save-trajectory", help="write the played (T, 9) trajectory to this .npy file")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object")
    p.add_argument("--video", help="render the episode: .gif or .mp4 (animation) or .png (image strip)")
    p.add_argument("--foods-file", help="a food YAML file instead of the packaged library")
    p.set_defaults(handler=_rollout)

    s = subparsers.add_parser("scene", help="print the scene geometry for a seed")
    s.add_argument("--seed", type=int, required=True)
    s.add_argument("--json", action="store_true", help="print exactly one JSON object")
    s.set_defaults(handler=_scene)

    f = subparsers.add_parser("foods", help="list the foods with split and quantity levels")
    f.add_argument("--json", action="store_true", help="print exactly one JSON object")
    f.add_argument("--foods-file", help="a food YAML file instead of the packaged library")
    f.set_defaults(handler=_foods)


def _rollout(args: argparse.Namespace) -> int:
    from grits_lab.sim.config import SimConfig
    from grits_lab.sim.foods import level_count, load_foods

    video = Path(args.video) if args.video else None
    if video is not None and video.suffix.lower() not in (".gif", ".mp4", ".png"):
        raise InputError(f"--video must end in .gif, .mp4 or .png, got {video.name!r}")
    # Check the cheap things first so bad input fails fast, before the simulator starts.
    foods = load_foods(args.foods_file)
    food = foods.get(args.food)
    level_count(food, args.food, args.quantity)
    trajectory = None
    if args.trajectory:
        from grits_lab.sim.episode import load_trajectory

        trajectory = load_trajectory(args.trajectory)

    from grits_lab.sim.env import ScoopEnv
    from grits_lab.sim.episode import run_episode

    env = ScoopEnv(SimConfig(foods_file=args.foods_file))
    frames: list[Any] = []
    on_step = None
    if video is not None:
        every = 1 if video.suffix.lower() != ".png" else 8

        def on_step(t: int, env: Any, obs: Any) -> None:
            if t % every == 0:
                import numpy as np

                images = env.render_cameras()
                frames.append(np.concatenate([im.rgb for im in images.values()], axis=1))

    try:
        record, played = run_episode(env, args.food, args.quantity, args.seed, trajectory, on_step=on_step)
    finally:
        env.close()
    if args.save_trajectory:
        import numpy as np

        from grits_lab.io import atomic_path

        with atomic_path(args.save_trajectory) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, played.astype(np.float32))
    if video is not None:
        _write_video(video, frames)
    summary = record.summary()
    summary["spilled_over_time"] = record.spilled_over_time
    if args.json:
        print(json.dumps(summary))
    else:
        for key in ("food", "split", "quantity", "seed", "n_particles", "spilled", "scooped", "spoon_coverage",
                    "scoop_success", "spillage", "scoop_failure", "first_spill_step", "ik_failures", "n_steps", "wall_time_s"):
            print(f"{key:>18}: {summary[key]}")
        if video is not None:
            print(f"{'video':>18}: {video}")
    return 0


def _write_video(path: Path, frames: list[Any]) -> None:
    from grits_lab.sim.video import write_video

    write_video(path, frames, fps=10.0)


def _scene(args: argparse.Namespace) -> int:
    from grits_lab.sim.env import ScoopEnv

    env = ScoopEnv()
    try:
        env.reset(seed=args.seed, options={"n_particles": 0})
        scene = env.scene().to_dict()
    finally:
        env.close()
    scene["seed"] = args.seed
    if args.json:
        print(json.dumps(scene))
    else:
        for key, value in scene.items():
            if key != "cameras":
                print(f"{key}: {value}")
        for cam in scene["cameras"]:
            print(f"camera {cam['name']}: {cam['width']}x{cam['height']}, camera_to_world {cam['camera_to_world']}")
    return 0


def _foods(args: argparse.Namespace) -> int:
    from grits_lab.sim.foods import load_foods

    library = load_foods(args.foods_file)
    rows = [{"food": name, "split": f.split, "levels": dict(f.levels), "success_rule": f.success_rule,
             "shapes": sorted({c.shape for c in f.components}), "description": f.description}
            for name, f in library.foods.items()]
    if args.json:
        print(json.dumps({"foods": rows}))
    else:
        for r in rows:
            levels = ", ".join(f"{k}={v}" for k, v in r["levels"].items())
            print(f"{r['food']:<16} {r['split']:<7} {levels:<34} {'/'.join(r['shapes'])}", file=sys.stdout)
    return 0
