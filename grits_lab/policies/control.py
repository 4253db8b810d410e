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
    # A diagnostic, 0 in every protocol config: every executed scoop action (and the settling hold)
    # is moved rigidly by this many metres, along a direction drawn from the episode's seed, so a
    # run on the same seeds tells how often an outcome changes when the spoon goes where the policy
    # asked, give or take a distance no observation resolves (docs/evaluation.md, "Outcome sensitivity").
    action_offset: float = 0.0
    # Which seeded set of directions the offset takes: 0, 1, ... give independent nudges of the same
    # size on the same seeds (a second draw tells a nudge's chance part from the nudge's own effect).
    action_offset_draw: int = 0
    # A diagnostic, null in every protocol config: the plan with this index (0 = the scoop's first)
    # draws its initial noise from draw `branch_draw` instead of the episode's own, every other plan
    # from the episode's own. Runs on the same seeds that differ only in `branch_draw` share every
    # step before that plan and then execute another sample of the diffusion policy from one and the
    # same state (docs/evaluation.md, "Branches from one state"). Draw 0 is the unbranched episode.
    # With a branch plan, `action_offset` moves the actions from that plan on only: the same sample,
    # nudged, from the same state.
    branch_plan: int | None = None
    branch_draw: int = 0

    def __post_init__(self) -> None:
        require(self.max_steps >= 1, "scoop.max_steps", self.max_steps, "at least 1")
        require(self.still_tolerance > 0, "scoop.still_tolerance", self.still_tolerance, "positive")
        require(self.min_steps >= 0, "scoop.min_steps", self.min_steps, "non-negative")
        require(self.n_action_steps is None or self.n_action_steps >= 1, "scoop.n_action_steps", self.n_action_steps, "at least 1 or null")
        require(self.settle_steps >= 0, "scoop.settle_steps", self.settle_steps, "non-negative")
        require(0.0 <= self.action_offset <= 0.01, "scoop.action_offset", self.action_offset,
                "in [0, 0.01] metres (a diagnostic nudge, not a motion: 0.0005 is half a millimetre)")
        require(self.action_offset_draw >= 0, "scoop.action_offset_draw", self.action_offset_draw, "non-negative")
        require(self.action_offset_draw == 0 or self.action_offset > 0, "scoop.action_offset_draw", self.action_offset_draw,
                "0 unless scoop.action_offset sets a nudge to draw directions for")
        require(self.branch_plan is None or self.branch_plan >= 0, "scoop.branch_plan", self.branch_plan,
                "a plan index (0 = the scoop's first) or null")
        require(self.branch_draw >= 0, "scoop.branch_draw", self.branch_draw, "non-negative")
        require(self.branch_draw == 0 or self.branch_plan is not None, "scoop.branch_draw", self.branch_draw,
                "0 unless scoop.branch_plan names the plan that branches")

    def plan_noise_keys(self, plan: int) -> tuple[object, ...]:
        """The keys after the episode's seed (`derive_seed(seed, *keys)`) of plan `plan`'s initial noise:
        ("plan", plan), with ("branch", branch_draw) added at `branch_plan` when `branch_draw` > 0."""
        if self.branch_plan is not None and self.branch_draw > 0 and plan == self.branch_plan:
            return ("plan", plan, "branch", self.branch_draw)
        return ("plan", plan)

    def record_columns(self) -> dict[str, float | int]:
        """The record columns of the diagnostic settings, as evaluation writes them:
        `scoop_action_offset_m` and `scoop_action_offset_draw` (0 without an offset),
        `scoop_branch_plan` (-1: none) and `scoop_branch_draw`. A record without them (made before
        they were recorded) ran with the defaults."""
        return {"scoop_action_offset_m": float(self.action_offset),
                "scoop_action_offset_draw": int(self.action_offset_draw) if self.action_offset else 0,
                "scoop_branch_plan": -1 if self.branch_plan is None else int(self.branch_plan),
                "scoop_branch_draw": int(self.branch_draw)}

    def offset_vector(self, seed: int) -> np.ndarray:
        """(9,) what is added to every executed scoop action: `action_offset` metres in position along
        a unit direction drawn uniformly on the sphere from `seed` (the episode's) and
        `action_offset_draw`, no rotation. Zeros when `action_offset` is 0."""
        offset = np.zeros(9)
        if self.action_offset > 0.0:
            draw = ("action-offset",) if self.action_offset_draw == 0 else ("action-offset", self.action_offset_draw)
            direction = np.random.default_rng(derive_seed(int(seed), *draw)).normal(size=3)
            offset[:3] = self.action_offset * direction / np.linalg.norm(direction)
        return offset


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
