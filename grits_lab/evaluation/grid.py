"""Which episodes a run plays: foods x quantity levels x trials, each with a seed derived from a root seed.

An evaluation config is an `EpisodeGrid` (the test episodes: experiments/evaluate*.yaml, top-level
`foods`, `levels`, `trials`, `seed`), and so is a sweep's `validation` block (the tuning episodes,
sweeps/*.yaml): one set of checks and one rule for the episodes and their seeds serves both.
Light on purpose (no simulator, no torch): the sweep's config imports it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from grits_lab.config import require
from grits_lab.errors import ConfigError
from grits_lab.records import UNSEEN_FOODS
from grits_lab.seeding import derive_seed

if TYPE_CHECKING:
    from grits_lab.sim.foods import FoodLibrary



@dataclass(frozen=True)
class EpisodeKey:
    """One (food, level, trial) with its seed; the same for every method."""

    food: str
    level: str
    trial: int
    seed: int
    split: str = "unseen"


MAX_TRIALS = 10_000  # trials per food and level in one run: its episode list is built before the first episode
MAX_TRIAL_INDEX = 2**31 - 1  # the last trial index a record may hold


@dataclass
class EpisodeGrid:
    """Foods x quantity levels x trials; episode seed = derive_seed(seed, food, level, trial).

    The trials played are first_trial .. first_trial + trials - 1 (0-based). A trial's seed depends on
    its index only, so trials 5-9 of a 10-trial protocol (`first_trial: 5, trials: 5`) are the same
    episodes as in the whole run: a protocol split across machines or sittings is reported as one by
    `grits-lab report RUN OTHER_RUN`.

    Foods may define different levels (orange has one): a listed level a food lacks is skipped
    for that food, and a level is a typo only when no listed food has it (`keys`).
    """

    foods: list[str] = field(default_factory=lambda: list(UNSEEN_FOODS))
    levels: list[str] = field(default_factory=list)  # empty: every level each food defines
    trials: int = 5
    first_trial: int = 0  # index of the first trial played
    seed: int = 0  # root seed

    def __post_init__(self) -> None:
        require(len(self.foods) >= 1, "foods", self.foods, "a non-empty list")
        require(len(set(self.foods)) == len(self.foods), "foods", self.foods, "without repeats")
        require(len(set(self.levels)) == len(self.levels), "levels", self.levels, "without repeats")
        require(1 <= self.trials <= MAX_TRIALS, "trials", self.trials,
                f"in [1, {MAX_TRIALS}] (per food and level; a larger protocol runs in parts, split by `first_trial`)")
        require(self.first_trial >= 0, "first_trial", self.first_trial, "non-negative")
        require(self.first_trial <= MAX_TRIAL_INDEX - self.trials, "first_trial", self.first_trial,
                f"in [0, {MAX_TRIAL_INDEX} - trials]")
        require(self.seed >= 0, "seed", self.seed, "non-negative")

    def keys(self, library: "FoodLibrary", key_prefix: str = "") -> list[EpisodeKey]:
        """Every episode, food outermost, then level, then trial; ConfigError naming `<key_prefix>foods`
        or `<key_prefix>levels` for a food the library lacks or a level no listed food has."""
        from grits_lab.sim.foods import check_food_names

        check_food_names(library, self.foods, self.levels, key_prefix)
        keys = []
        for food in self.foods:
            spec = library.get(food)
            present = [lv for lv in self.levels or list(spec.levels) if lv in spec.levels]
            if self.levels and not present:
                raise ConfigError(f"`{key_prefix}levels` {self.levels} names no level of food {food!r} "
                                  f"(its levels: {', '.join(spec.levels)})")
            for level in present:
                for trial in range(self.first_trial, self.first_trial + self.trials):
                    keys.append(EpisodeKey(food, level, trial, derive_seed(self.seed, food, level, trial), spec.split))
        return keys
