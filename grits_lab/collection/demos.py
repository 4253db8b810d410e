"""Demonstration dataset: the randomized scripted expert over training foods x levels x bowl configurations.

Each episode stores per step what the policies need (contract 4): the commanded spoon pose
(`action`), the measured spoon pose before it (`ee_pose`), the arm's joint state, the composite
point cloud and, when configured, RGB-D images at the policy's resolution; and per episode its
food, level, bowl configuration, seed and the metrics measured from the particles.
A bowl configuration is one placement of the target bowl in the workspace (drawn from its own seed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np

from grits_lab.config import require
from grits_lab.perception.composite import CloudConfig
from grits_lab.records import CPU_KERNELS
from grits_lab.runners.executor_config import ExecutorConfig
from grits_lab.runners.spec import EpisodeSpec
from grits_lab.seeding import derive_seed, make_rng
from grits_lab.sim.sim_config import SimConfig
from grits_lab.versions import cpu_kernels

TRAINING_FOODS = ["brown_rice", "soybeans", "mung_beans", "chocolate_balls", "dried_jujube", "orange"]


@dataclass
class ImageConfig:
    # RGB-D per step at the policy's resolution (paper: 240 x 320). Off by default: images are the
    # largest part of a dataset and rendering them is the slowest part of an episode.
    enabled: bool = False
    height: int = 96
    width: int = 128
    # Cameras to store, by name (empty: all cameras of the sim config).
    cameras: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        require(self.height >= 8 and self.width >= 8, "images.height/width", (self.height, self.width), "at least 8 pixels")


@dataclass
class DemosConfig:
    retired_keys: ClassVar[dict[str, str]] = {"output": "output_dir"}

    kind: Literal["demos"] = "demos"
    output_dir: str = "results/datasets/demos"
    seed: int = 0
    foods: list[str] = field(default_factory=lambda: list(TRAINING_FOODS))
    # Quantity levels to use (empty: every level each food defines; orange has one).
    levels: list[str] = field(default_factory=list)
    bowl_configs: int = 5
    # Cap on the number of episodes (null: all foods x levels x bowl configs = 80 by default).
    max_episodes: int | None = None
    sim: SimConfig = field(default_factory=SimConfig)
    cloud: CloudConfig = field(default_factory=CloudConfig)
    images: ImageConfig = field(default_factory=ImageConfig)
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)

    def __post_init__(self) -> None:
        require(len(self.foods) >= 1, "foods", self.foods, "a non-empty list")
        require(self.bowl_configs >= 1, "bowl_configs", self.bowl_configs, "at least 1")
        require(self.max_episodes is None or self.max_episodes >= 1, "max_episodes", self.max_episodes, "at least 1 or null")

    def identity(self) -> dict[str, Any]:
        """What determines the data (the executor and the output path do not)."""
        from grits_lab.collection.driver import collection_identity

        return collection_identity(self)


@dataclass
class DemoEpisodeParams:
    """Everything a worker needs for one demonstration besides the spec's food, level and seed."""

    sim: SimConfig
    cloud: CloudConfig
    images: ImageConfig
    bowl_config: int
    food_split: str


def plan_demos(config: DemosConfig) -> list[EpisodeSpec]:
    """One spec per (food, level, bowl configuration), seeds derived from the root seed."""
    from grits_lab.sim.foods import check_food_names, load_foods

    library = load_foods(config.sim.foods_file)
    check_food_names(library, config.foods, config.levels)
    specs = []
    # Bowl configuration outermost, so that a `max_episodes` cap still covers every food and level.
    for b in range(config.bowl_configs):
        for food in config.foods:
            food_spec = library.get(food)
            for level in config.levels or list(food_spec.levels):
                if level not in food_spec.levels:
                    continue  # e.g. orange has one level only
                params = DemoEpisodeParams(sim=config.sim, cloud=config.cloud, images=config.images, bowl_config=b, food_split=food_spec.split)
                specs.append(
                    EpisodeSpec(
                        episode_id=f"{food}-{level}-b{b}",
                        work=demo_episode,
                        seed=derive_seed(config.seed, "demo", food, level, b),
                        food=food,
                        level=level,
                        params={"demo": params},
                    )
                )
    return specs[: config.max_episodes] if config.max_episodes else specs


def _images(cameras: list[dict[str, Any]], config: ImageConfig) -> np.ndarray:
    """(cams, 4, H, W) float16: RGB in [0, 1] and depth in metres, resized to the policy's resolution."""
    from PIL import Image

    size = (config.width, config.height)
    out = []
    for cam in cameras:
        rgb = Image.fromarray(np.asarray(cam["rgb"], dtype=np.uint8)[..., :3]).resize(size, Image.BILINEAR)
        depth = Image.fromarray(np.asarray(cam["depth"], dtype=np.float32)).resize(size, Image.NEAREST)
        out.append(np.concatenate([np.asarray(rgb, dtype=np.float32).transpose(2, 0, 1) / 255.0, np.asarray(depth)[None]]))
    return np.stack(out).astype(np.float16)


def demo_episode(spec: EpisodeSpec, context: Any) -> dict[str, Any]:
    """Run the randomized scripted expert for one (food, level, bowl configuration); record every step.

    The target bowl's placement (the bowl configuration) and the expert's randomization are drawn
    from the episode's seed, so the episode replays exactly from its spec.
    """
    from grits_lab.config import config_fingerprint
    from grits_lab.perception.env_clouds import builder_for_env, camera_list, scene_clouds
    from grits_lab.sim.env import worker_env
    from grits_lab.sim.expert import expert_trajectory

    p: DemoEpisodeParams = spec.params["demo"]
    env = worker_env(context, p.sim)
    builder = context.cached(("cloud-builder", config_fingerprint(p.cloud)), lambda: builder_for_env(p.cloud, env))
    obs, info = env.reset(seed=spec.seed, options={"food": spec.food, "level": spec.level})
    plan = expert_trajectory(env.scene(), make_rng(derive_seed(spec.seed, "expert")), env.config.control_hz)
    actions, ee_poses, joints, clouds, images, spilled = [], [], [], [], [], []
    for t, action in enumerate(plan):
        rendered = env.render_cameras()
        clouds.append(scene_clouds(builder, env, seed=derive_seed(spec.seed, "cloud", t), cameras=rendered)["cloud"].astype(np.float16))
        if p.images.enabled:
            images.append(_images(camera_list(rendered, p.images.cameras), p.images))
        ee_poses.append(np.asarray(obs["ee_pose"], dtype=np.float32))
        joints.append(np.asarray(obs["joint_pos"], dtype=np.float32))
        actions.append(np.asarray(action, dtype=np.float32))
        obs, _, terminated, truncated, info = env.step(action)
        spilled.append(int(info["spilled"]))
        if terminated or truncated:
            break
    metrics = env.metrics()
    arrays = {
        "action": np.stack(actions),
        "ee_pose": np.stack(ee_poses),
        "joint_pos": np.stack(joints),
        "cloud": np.stack(clouds),
        "spilled_over_time": np.asarray(spilled, dtype=np.int32),
    }
    if images:
        arrays["rgbd"] = np.stack(images)
    meta = {
        "food": spec.food,
        "split": p.food_split,
        "level": spec.level,
        "seed": spec.seed,
        "bowl_config": p.bowl_config,
        "steps": len(actions),
        "target_bowl_x": float(env.target_bowl_pose()[0, 3]),
        "target_bowl_y": float(env.target_bowl_pose()[1, 3]),
        "spilled_any": bool(metrics["spilled"] > 0),
        CPU_KERNELS: cpu_kernels(),  # grits_lab/versions.py: what the worker computed with
        **{k: v for k, v in metrics.items() if isinstance(v, (bool, int, float, str)) or v is None},
        **metrics["spill_attribution"],
    }
    return {"arrays": arrays, "meta": meta}
