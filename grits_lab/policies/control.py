"""The scoop controller's side of an episode: the chunk it returns, how chunks are executed, and scoops played during training.

The controller protocol (duck-typed; the episode loop is grits_lab/evaluation/task_episode.py):

    controller.cloud_steps: int          newest steps whose composite cloud the controller reads
    controller.stops_when_still: bool    (optional) a chunk that holds the pose ends the scoop
    controller.n_action_steps: int       (optional) actions executed per chunk; default all
    controller.reset(scene) -> None      once per episode, before the first plan
    controller.plan(history, scene) -> Chunk | None
                                         the next actions (k, 9) world frame; None ends the scoop

The episode loop executes `n_action_steps` of each chunk and plans again (receding horizon), so a
controller never steps the simulator itself. The baselines in this package and the learned
methods' adapters (grits_lab/evaluation/controllers.py) all return `Chunk`s. Scoops during
training are played by a callable handed to the training loop from above (`Rollouts`), as
diffusion_policy's workspace hands its env runner the policy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np

from grits_lab.config import require
from grits_lab.perception.composite import CloudConfig
from grits_lab.seeding import derive_seed
from grits_lab.sim.sim_config import SimConfig


@dataclass
class Chunk:
    """What a controller's `plan` returns: the next actions and what the planner measured."""

    actions: np.ndarray  # (k, 9) world-frame spoon poses
    diagnostics: dict[str, Any] = field(default_factory=dict)
    plan_time_s: float = 0.0
    # (k, 9) the unguided sample's chunk from the same noise, when the sampler made one: what the
    # policy itself proposes, on which "the policy holds" is judged (guidance refines a motion;
    # it is not the policy asking to move on).
    unguided_actions: np.ndarray | None = None


@dataclass
class ScoopSettings:
    """The learned scoop: receding-horizon execution and when the scoop counts as complete."""

    max_steps: int = 120  # actions (10 Hz) before the scoop is cut off (SCONE's probe included)
    # A planned chunk that moves the spoon less than this (metres, every waypoint) ends the scoop:
    # the policy holds its final pose, as demonstrations do after they finish.
    still_tolerance: float = 0.004
    min_steps: int = 24  # never stop before this many actions (the spoon starts still)
    n_action_steps: int | None = None  # null: the policy's own (12 at the paper's settings)
    settle_steps: int = 5  # actions holding the last pose before the scoop is judged

    def __post_init__(self) -> None:
        require(self.max_steps >= 1, "scoop.max_steps", self.max_steps, "at least 1")
        require(self.still_tolerance > 0, "scoop.still_tolerance", self.still_tolerance, "positive")
        require(self.min_steps >= 0, "scoop.min_steps", self.min_steps, "non-negative")
        require(self.n_action_steps is None or self.n_action_steps >= 1, "scoop.n_action_steps", self.n_action_steps, "at least 1 or null")
        require(self.settle_steps >= 0, "scoop.settle_steps", self.settle_steps, "non-negative")


# The record columns of a scoop hook, at the values of none (`ScoopHook.record_columns`). Every
# record has carried them since scoop diagnostics were first recorded, so records with and without
# a hook stay one table; their names are those of the perturbations studies/outcome_sensitivity runs
# through a hook (a nudge of the executed actions, another noise draw at one plan).
NO_HOOK_COLUMNS: dict[str, float | int] = {"scoop_action_offset_m": 0.0, "scoop_action_offset_draw": 0,
                                           "scoop_branch_plan": -1, "scoop_branch_draw": 0}


class ScoopHook:
    """The scoop loop's one extension point, as a Gymnasium wrapper grows an unchanged env: this base
    changes nothing, and a subclass perturbs the scoop from outside the framework.

    grits_lab/evaluation/task_episode.py `run_scoop` asks it, for plan `plan` (0 = the scoop's first;
    -1 before any) of the episode with seed `seed`:
      noise_keys(plan) -> the keys after the episode's seed (`derive_seed(seed, *keys)`) of that plan's
          initial noise, for the controllers that sample (DiffusionController); ("plan", plan) here.
      executed(action, seed, plan) -> (9,) what the simulator executes for the planned action (9,);
          the history the controller reads keeps what it asked for. Here `action` as float64 (a
          copy plus a zero offset, bit for bit what the loop has always sent).
    Evaluation writes `record_columns()` into every record, refuses to resume records written under
    other values, and calls `check(config)` before any episode (raise InputError for a config the
    hook cannot run with). A hook is pickled to the workers: keep it plain data.
    """

    def noise_keys(self, plan: int) -> tuple[object, ...]:
        return ("plan", plan)

    def executed(self, action: np.ndarray, seed: int, plan: int) -> np.ndarray:
        return action + np.zeros(9)

    def record_columns(self) -> dict[str, float | int]:
        return dict(NO_HOOK_COLUMNS)

    def check(self, config: Any) -> None:
        return None


@dataclass
class RolloutSettings:
    """Scoops played during training (`every` steps; 0 = never): how many, how each scoop is
    executed, the clouds the policy sees and the simulator they run in."""

    every: int = 0
    episodes: int = 6
    scoop: ScoopSettings = field(default_factory=ScoopSettings)
    cloud: CloudConfig = field(default_factory=lambda: CloudConfig(n_points=256, cad_surface_samples=4000))
    sim: SimConfig = field(default_factory=SimConfig)

    def __post_init__(self) -> None:
        require(self.every >= 0, "rollout.every", self.every, "non-negative (0 = never)")
        require(self.episodes >= 1, "rollout.episodes", self.episodes, "at least 1")


def rollout_episodes(pairs: list[tuple[str, str]], n: int, seed: int) -> list[tuple[str, str, int]]:
    """(food, level, seed) of the `n` scoops: the (food, level) pairs in turn, seeds derived from `seed`."""
    ordered = sorted(set(pairs))
    return [(*ordered[i % len(ordered)], derive_seed(seed, "rollout", i)) for i in range(n)]


class Controller(Protocol):
    """What the episode loop asks for the next chunk of actions (the protocol in this module's docstring).

    `history` is the episode's measured spoon poses and clouds so far
    (grits_lab.evaluation.controllers.ObsHistory); `scene` gives read access to the cameras and
    the spoon's sensors (grits_lab.evaluation.episode_scene.EpisodeScene). Optional attributes:
    `stops_when_still` (bool), `n_action_steps` (int), `image_steps` (int).
    """

    cloud_steps: int

    def reset(self, scene: Any) -> None: ...

    def plan(self, history: Any, scene: Any) -> Chunk | None: ...


class Rollouts(Protocol):
    """Plays the training scoops: `rollouts(policy)` -> {"rollout_scoop_success": ..., "rollout_spillage": ...}."""

    def __call__(self, policy: Any) -> dict[str, float]: ...

    def close(self) -> None: ...


# (settings, [(food, level, seed), ...]) -> Rollouts; grits_lab.evaluation.rollouts.ScoopRollouts is one.
RolloutsFactory = Callable[[RolloutSettings, list[tuple[str, str, int]]], Rollouts]


def is_still(chunk: Chunk, pose: np.ndarray, tolerance: float) -> bool:
    """True when every action of the policy's own proposal (the unguided chunk from the same noise
    when there is one, else the chunk) keeps the spoon within `tolerance` (metres) of `pose` (9,):
    the policy holds."""
    actions = chunk.actions if chunk.unguided_actions is None else chunk.unguided_actions
    return bool(np.all(np.linalg.norm(actions[:, :3] - pose[None, :3], axis=1) < tolerance))
