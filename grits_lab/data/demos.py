"""Demonstration dataset: the randomized scripted expert over training foods x levels x bowl configurations.

Each episode stores per step what the policies need (contract 4): the commanded spoon pose
(`action`), the measured spoon pose before it (`ee_pose`), the arm's joint state, the composite
point cloud and, when configured, RGB-D images at the policy's resolution; and per episode its
food, level, bowl configuration, seed and the metrics measured from the particles.
A bowl configuration is one placement of the target bowl in the workspace (drawn from its own seed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from grits_lab.config import config_to_dict, require
from grits_lab.perception.composite import CloudConfig
from grits_lab.runners.config import ExecutorConfig
from grits_lab.runners.spec import EpisodeSpec
from grits_lab.seeding import derive_seed, make_rng

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
    kind: Literal["demos"] = "demos"
    output: str = "results/datasets/demos"
    seed: int = 0
    foods: list[str] = field(default_factory=lambda: list(TRAINING_FOODS))
    # Quantity levels to use (empty: every level each food defines; orange has one).
    levels: list[str] = field(default_factory=list)
    bowl_configs: int = 5
    # Cap on the number of episodes (null: all foods x levels x bowl configs = 80 by default).
    max_episodes: int | None = None
    # Sim settings (grits_lab.sim.SimConfig keys); empty = the sim's defaults.
    sim: dict[str, Any] = field(default_factory=dict)
    cloud: CloudConfig = field(default_factory=CloudConfig)
    images: ImageConfig = field(default_factory=ImageConfig)
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)

    def __post_init__(self) -> None:
        require(len(self.foods) >= 1, "foods", self.foods, "a non-empty list")
        require(self.bowl_configs >= 1, "bowl_configs", self.bowl_configs, "at least 1")
        require(self.max_episodes is None or self.max_episodes >= 1, "max_episodes", self.max_episodes, "at least 1 or null")

    def identity(self) -> dict[str, Any]:
        """What determines the data (the executor and the output path do not)."""
        d = config_to_dict(self)
        d.pop("executor")
        d.pop("output")
        return d


@dataclass
class DemoEpisodeParams:
    """Everything a worker needs for one demonstration besides the spec's food, level and seed."""

    sim: Any
    cloud: CloudConfig
    images: ImageConfig
    bowl_config: int
    food_split: str


def plan_demos(config: DemosConfig) -> list[EpisodeSpec]:
    """One spec per (food, level, bowl configuration), seeds derived from the root seed."""
    from grits_lab.config import config_from_dict
    from grits_lab.sim import SimConfig
    from grits_lab.sim.foods import load_foods

    sim = config_from_dict(SimConfig, config.sim, "sim")
    library = load_foods(sim.foods_file)
    specs = []
    # Bowl configuration outermost, so that a `max_episodes` cap still covers every food and level.
    for b in range(config.bowl_configs):
        for food in config.foods:
            food_spec = library.get(food)
            for level in config.levels or list(food_spec.levels):
                if level not in food_spec.levels:
                    continue  # e.g. orange has one level only
                params = DemoEpisodeParams(sim=sim, cloud=config.cloud, images=config.images, bowl_config=b, food_split=food_spec.split)
                specs.append(
                    EpisodeSpec(
                        episode_id=f"{food}-{level}-b{b}",
                        work="demo",
                        seed=derive_seed(config.seed, "demo", food, level, b),
                        food=food,
                        level=level,
                        params={"demo": params},
                    )
                )
    return specs[: config.max_episodes] if config.max_episodes else specs
