"""`grits-lab rollout`, `grits-lab scene` and `grits-lab foods`: the simulated world from the command line."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from grits_lab.cli.flags import retire
from grits_lab.io import to_json


def register(subparsers: argparse._SubParsersAction) -> None:
    _register_foods(subparsers)  # the workflow's order: the foods, the scene, then an episode in it
    s = subparsers.add_parser("scene", help="print the scene geometry for an episode seed")
    s.add_argument("--episode-seed", type=int, required=True, metavar="N", help="episode seed (world, target bowl)")
    s.add_argument("--json", action="store_true", help="print exactly one JSON object")
    retire(s, "--seed", "--episode-seed")
    s.set_defaults(handler=_scene)

    p = subparsers.add_parser("rollout", help="play a trajectory (or the scripted expert) and print the episode record")
    p.add_argument("--food", required=True, help="food name (see `grits-lab foods`)")
    p.add_argument("--level", required=True, help="quantity level of that food, e.g. low / medium / high")
    p.add_argument("--episode-seed", type=int, required=True, metavar="N", help="episode seed (world, particles, target bowl, expert)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--trajectory", help="(T, 9) xyz + 6-D rotation or (T, 7) xyz + quaternion xyzw .npy, 10 Hz, world frame")
    src.add_argument("--expert", action="store_true", help="play the seeded, randomized scripted expert scoop")
    p.add_argument("--save-trajectory", help="write the played (T, 9) trajectory to this .npy file")
    p.add_argument("--json", action="store_true", help="print exactly one JSON object")
    p.add_argument("--video", help="render the episode: .gif or .mp4 (animation) or .png (image strip)")
    p.add_argument("--foods-file", help="a food YAML file instead of the packaged library")
    retire(p, "--quantity", "--level")
    retire(p, "--seed", "--episode-seed")
    p.set_defaults(handler=_rollout)


def _register_foods(subparsers: argparse._SubParsersAction) -> None:
    f = subparsers.add_parser("foods", help="list the foods with split, quantity levels and their settled fill heights")
    f.add_argument("--json", action="store_true", help="print exactly one JSON object")
    f.add_argument("--foods-file", help="a food YAML file instead of the packaged library")
    f.add_argument("--food", action="append", help="only this food (repeatable)")
    f.add_argument("--bowl-seed", type=int, default=0, metavar="N", help="seed of the settled bowl whose fill height is measured (default 0)")
    f.add_argument("--no-settle", action="store_true", help="skip building and settling each level (no fill heights; instant)")
    retire(f, "--seed", "--bowl-seed")
    f.set_defaults(handler=_foods)


def _rollout(args: argparse.Namespace) -> int:
    from grits_lab.sim.sim_config import SimConfig
    from grits_lab.sim.foods import level_count, load_foods

    from grits_lab.sim.video import VIDEO_SUFFIXES, check_video_path

    video = check_video_path(args.video, VIDEO_SUFFIXES + (".png",)) if args.video else None
    if args.save_trajectory:
        from grits_lab.io import check_writable_file

        check_writable_file(args.save_trajectory)
    # Check the cheap things first so bad input fails fast, before the simulator starts.
    foods = load_foods(args.foods_file)
    food = foods.get(args.food)
    level_count(food, args.food, args.level)
    trajectory = None
    if args.trajectory:
        from grits_lab.sim.playback import load_trajectory

        trajectory = load_trajectory(args.trajectory)

    from grits_lab.sim.env import ScoopEnv
    from grits_lab.sim.playback import play_episode

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
        record, played = play_episode(env, args.food, args.level, args.episode_seed, trajectory, on_step=on_step)
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
        print(to_json(summary, indent=None))
    else:
        for key in ("protocol", "food", "split", "quantity", "seed", "n_particles", "spilled", "scooped", "spoon_coverage",
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
        env.reset(seed=args.episode_seed, options={"n_particles": 0})
        scene = env.scene().to_dict()
    finally:
        env.close()
    scene["seed"] = args.episode_seed
    if args.json:
        print(to_json(scene, indent=None))
    else:
        for key, value in scene.items():
            if key != "cameras":
                print(f"{key}: {value}")
        for cam in scene["cameras"]:
            print(f"camera {cam['name']}: {cam['width']}x{cam['height']}, camera_to_world {cam['camera_to_world']}")
    return 0


def level_survey(library, names: list[str], seed: int = 0, settle: bool = True, config=None) -> list[dict]:
    """Per food and level: the amount, the particle count and (when `settle`) the settled fill height.

    Each level is built and settled with `seed`; fill height in metres (90th percentile of particle
    tops above the source bowl's inner floor), layers = fill height / the largest piece height.
    """
    from grits_lab.sim.foods import level_count

    env = None
    rows = []
    try:
        for name in names:
            food = library.get(name)
            levels = {}
            for level, amount in food.levels.items():
                entry = {"amount": amount.describe(), "n_particles": level_count(food, name, level)}
                if settle:
                    if env is None:
                        from grits_lab.sim.sim_config import SimConfig
                        from grits_lab.sim.env import ScoopEnv

                        env = ScoopEnv(config or SimConfig())
                    env.reset(seed=seed, options={"food_spec": food, "level": level})
                    height = env.fill_height()
                    piece = 2 * max(p.radius for p in env.world.particle_components)
                    entry.update(fill_height_m=round(height, 4), layers=round(height / piece, 2), settle_time_s=env.world.settle_time_s)
                levels[level] = entry
            rows.append({"food": name, "split": food.split, "success_rule": food.success_rule,
                         "shapes": sorted({c.shape for c in food.components}),
                         "coarse_grain": max(c.coarse_grain for c in food.components),
                         "levels": levels, "description": food.description})
    finally:
        if env is not None:
            env.close()
    return rows


def _foods(args: argparse.Namespace) -> int:
    from grits_lab.sim.sim_config import SimConfig
    from grits_lab.sim.foods import load_foods

    library = load_foods(args.foods_file)
    names = args.food or library.names()
    for name in names:
        library.get(name)  # unknown names fail before any world is built
    rows = level_survey(library, names, seed=args.bowl_seed, settle=not args.no_settle, config=SimConfig(foods_file=args.foods_file))
    if args.json:
        print(to_json({"seed": args.bowl_seed, "foods": rows}, indent=None))
    else:
        for r in rows:
            parts = []
            for k, v in r["levels"].items():
                amount = f"{100 * v['amount']['fill_height_m']:.1f} cm" if "fill_height_m" in v["amount"] else f"{v['amount']['pieces']} pieces"
                settled = f", settled {100 * v['fill_height_m']:.1f} cm" if "fill_height_m" in v else ""
                parts.append(f"{k}={amount} ({v['n_particles']} particles{settled})")
            print(f"{r['food']:<16} {r['split']:<7} {'/'.join(r['shapes']):<22} {'; '.join(parts)}", file=sys.stdout)
    return 0
