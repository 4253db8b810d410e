"""The evaluation's transfer and pour as the carry that ends a spillage trial (handed to grits_lab/collection)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from grits_lab.evaluation.episode_scene import EpisodeScene
from grits_lab.evaluation.task_episode import run_transfer

if TYPE_CHECKING:  # annotations only
    from grits_lab.perception.composite import CloudBuilder
    from grits_lab.sim.env import ScoopEnv
    from grits_lab.task.transfer_settings import TransferSettings


def carry_to_target(env: ScoopEnv, builder: CloudBuilder, seed: int, settings: TransferSettings) -> dict[str, Any]:
    """Stages 2 and 3 of the evaluation's task (`run_transfer`) from wherever the spoon is now:
    locate the target bowl from the cameras, lift, carry level, pour, settle. Returns
    `run_transfer`'s measurements; every step appends to the env's spilled-count history."""
    scene = EpisodeScene(env, builder, seed)
    scene.step = int(env.step_count)  # the episode's step: its cloud seeds follow the scoop's
    return run_transfer(env, scene, settings)

