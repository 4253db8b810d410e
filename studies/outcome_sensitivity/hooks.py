"""The outcome-sensitivity study's perturbations of the scoop, as one scoop hook (grits_lab/policies/control.py `ScoopHook`).

- The nudge: every executed scoop action (and the settling hold) moved rigidly by `offset` metres,
  along a direction drawn from the episode's seed, so a run on the same seeds tells how often an
  outcome changes when the spoon goes where the policy asked, give or take a distance no
  observation resolves. `offset_draw` 0, 1, ... give independent nudges of the same size on the
  same seeds (a second draw tells a nudge's chance part from the nudge's own effect).
- The branch: the plan with index `branch_plan` (0 = the scoop's first) draws its initial noise
  from draw `branch_draw` instead of the episode's own, every other plan from the episode's own.
  Runs on the same seeds that differ only in `branch_draw` share every step before that plan and
  then execute another sample of the diffusion policy from one and the same state. Draw 0 is the
  unbranched episode. With a branch plan, the nudge moves the actions from that plan on only: the
  same sample, nudged, from the same state.

The record columns are the framework's (`NO_HOOK_COLUMNS`): `scoop_action_offset_m`,
`scoop_action_offset_draw` (0 without an offset), `scoop_branch_plan` (-1: none), `scoop_branch_draw`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from grits_lab.errors import InputError
from grits_lab.policies import ScoopHook
from grits_lab.seeding import derive_seed


@dataclass(frozen=True)
class OutcomeHook(ScoopHook):
    """A nudge of `offset` metres (draw `offset_draw`), a branch at plan `branch_plan` (draw
    `branch_draw`), or both; the defaults change nothing."""

    offset: float = 0.0
    offset_draw: int = 0
    branch_plan: int | None = None
    branch_draw: int = 0

    def __post_init__(self) -> None:
        if not 0.0 <= self.offset <= 0.01:
            raise InputError(f"--offset must be in [0, 0.01] metres (a diagnostic nudge, not a motion: 0.0005 is half a "
                             f"millimetre). Got {self.offset}.")
        if self.offset_draw < 0 or self.branch_draw < 0:
            raise InputError(f"--draw must be non-negative. Got {min(self.offset_draw, self.branch_draw)}.")
        if self.offset_draw and not self.offset:
            raise InputError("a nudge draw needs a nudge: --offset must be positive")
        if self.branch_plan is not None and self.branch_plan < 0:
            raise InputError(f"--plan must be a plan index (0 = the scoop's first). Got {self.branch_plan}.")
        if self.branch_draw and self.branch_plan is None:
            raise InputError("a branch draw needs the plan that branches (--plan)")

    def noise_keys(self, plan: int) -> tuple[object, ...]:
        """("plan", plan), with ("branch", branch_draw) added at `branch_plan` when `branch_draw` > 0."""
        if self.branch_plan is not None and self.branch_draw > 0 and plan == self.branch_plan:
            return ("plan", plan, "branch", self.branch_draw)
        return ("plan", plan)

    def offset_vector(self, seed: int) -> np.ndarray:
        """(9,) what is added to an executed scoop action: `offset` metres in position along a unit
        direction drawn uniformly on the sphere from `seed` (the episode's) and `offset_draw`, no
        rotation. Zeros when `offset` is 0."""
        vector = np.zeros(9)
        if self.offset > 0.0:
            draw = ("action-offset",) if self.offset_draw == 0 else ("action-offset", self.offset_draw)
            direction = np.random.default_rng(derive_seed(int(seed), *draw)).normal(size=3)
            vector[:3] = self.offset * direction / np.linalg.norm(direction)
        return vector

    def executed(self, action: np.ndarray, seed: int, plan: int) -> np.ndarray:
        """`action` + `offset_vector(seed)`; with a branch plan, only from that plan on."""
        if self.branch_plan is not None and plan < self.branch_plan:
            return action + np.zeros(9)  # before the branch plan: shared with the unbranched episode
        return action + self.offset_vector(seed)

    def record_columns(self) -> dict[str, float | int]:
        return {"scoop_action_offset_m": float(self.offset),
                "scoop_action_offset_draw": int(self.offset_draw) if self.offset else 0,
                "scoop_branch_plan": -1 if self.branch_plan is None else int(self.branch_plan),
                "scoop_branch_draw": int(self.branch_draw)}

    def check(self, config: Any) -> None:
        """Only a diffusion policy's plans draw noise to branch on."""
        from grits_lab.evaluation.methods import METHODS

        if self.branch_plan is None:
            return
        other = [m for m in config.methods if m not in METHODS or METHODS[m].kind != "diffusion"]
        if other:
            raise InputError(f"a branch needs diffusion-policy methods (dp, dp_post, grits*); `methods` lists {', '.join(other)}")
