"""The sweep's typed config: search ranges for rho and s, objective, sampler, storage, episodes.

A sweep file (sweeps/NAME.yaml) is loaded into `StudyConfig` and checked on load, so a reversed
range, a log range through zero, a default outside its range or a validation food or level the
food library lacks fails before any storage is opened or any episode runs, with one line that
names the key.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Literal

from grits_lab.config import config_fingerprint, config_to_dict, load_config, require
from grits_lab.errors import ConfigError, InputError
from grits_lab.evaluation.grid import EpisodeGrid, EpisodeKey

if TYPE_CHECKING:
    from grits_lab.sim.foods import FoodLibrary

_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


# Evaluation configs that moved (a preset renamed to its tier, a study's config into studies/), under
# the path every stored study's identity hashed: a sweep that names the new path keeps resuming the
# studies it stored before the move.
IDENTITY_CONFIG_PATHS = {
    "experiments/evaluate_paper.yaml": "experiments/evaluate.yaml",
    "studies/brim_guidance/configs/evaluate_cpu_brim.yaml": "experiments/evaluate_cpu_brim.yaml",
}


@dataclass(frozen=True)
class FloatRangeConfig:
    """Search range of a float parameter; `log` samples uniformly in log space (needs low > 0)."""

    low: float
    high: float
    log: bool = False

    def check(self, key: str) -> None:
        require(math.isfinite(self.low), f"{key}.low", self.low, "a finite number")
        require(math.isfinite(self.high), f"{key}.high", self.high, "a finite number")
        require(self.low >= 0.0, f"{key}.low", self.low, ">= 0 (a negative guidance weight pushes toward spillage)")
        require(self.high > self.low, f"{key}.high", self.high, f"greater than {key}.low = {self.low}")
        if self.log:
            require(self.low > 0.0, f"{key}.low", self.low, "> 0 when `log: true`")

    def contains(self, value: float) -> bool:
        return self.low <= value <= self.high


@dataclass(frozen=True)
class IntRangeConfig:
    """Search range of an integer parameter, both ends included."""

    low: int
    high: int
    step: int = 1
    log: bool = False

    def check(self, key: str, upper: int) -> None:
        require(self.low >= 0, f"{key}.low", self.low, ">= 0")
        require(self.high > self.low, f"{key}.high", self.high, f"greater than {key}.low = {self.low}")
        require(self.high <= upper, f"{key}.high", self.high, f"<= train_timesteps = {upper} (s is on the training-step scale)")
        require(self.step >= 1, f"{key}.step", self.step, ">= 1")
        require((self.high - self.low) % self.step == 0, f"{key}.step", self.step, f"a divisor of high - low = {self.high - self.low}")
        if self.log:
            require(self.low >= 1, f"{key}.low", self.low, ">= 1 when `log: true`")
            require(self.step == 1, f"{key}.step", self.step, "1 when `log: true`")

    def contains(self, value: int) -> bool:
        return self.low <= value <= self.high and (value - self.low) % self.step == 0


@dataclass(frozen=True)
class GuidancePoint:
    """One (rho, s) setting, e.g. the paper's defaults that every study evaluates first."""

    rho: float
    s: int


@dataclass(frozen=True)
class ObjectiveConfig:
    """What a trial optimizes, from the success and spillage rates over the validation episodes.

    single: maximize success_rate - spillage_weight * spillage_rate.
    multi:  maximize success_rate and minimize spillage_rate (a Pareto front).
    `max_spillage` (either mode) adds the constraint spillage_rate <= max_spillage: the sampler
    prefers feasible trials and the best trial is chosen among feasible ones.
    """

    mode: Literal["single", "multi"] = "single"
    spillage_weight: float = 1.0
    max_spillage: float | None = None

    def __post_init__(self) -> None:
        require(math.isfinite(self.spillage_weight) and self.spillage_weight >= 0.0,
                "objective.spillage_weight", self.spillage_weight, "a finite number >= 0")
        if self.max_spillage is not None:
            require(0.0 <= self.max_spillage <= 1.0, "objective.max_spillage", self.max_spillage, "in [0, 1]")

    @property
    def directions(self) -> list[str]:
        return ["maximize"] if self.mode == "single" else ["maximize", "minimize"]

    @property
    def value_names(self) -> list[str]:
        return ["score"] if self.mode == "single" else ["success_rate", "spillage_rate"]


@dataclass(frozen=True)
class SamplerConfig:
    """The Optuna sampler. Each trial's sampler is seeded from (seed, trial number): reproducible
    for one worker, and different draws for workers that share a storage."""

    name: Literal["tpe", "random", "gp"] = "tpe"
    seed: int = 0
    n_startup_trials: int = 5

    def __post_init__(self) -> None:
        require(self.seed >= 0, "sampler.seed", self.seed, ">= 0")
        require(self.n_startup_trials >= 0, "sampler.n_startup_trials", self.n_startup_trials, ">= 0")


@dataclass
class ValidationConfig(EpisodeGrid):
    """The episodes every trial is evaluated on: an evaluation config's episode grid (foods x levels
    x trials, episode seed = derive_seed(seed, food, level, trial)), checked by the same code.

    Only the defaults differ: foods and levels must be named (the evaluation's default foods are
    the test foods), and the root seed is 7000. Use a root seed different from the final
    evaluation's so that tuning does not see test episodes.
    """

    foods: list[str]
    levels: list[str]  # empty: every level each food defines
    trials: int = 2
    seed: int = 7000


# Evaluation keys a sweep's `evaluation.overrides` may not set: the episode grid (the sweep's
# `validation` block sets it) and where and how episodes run, which change no result.
NOT_OVERRIDABLE = ("run_id", "output_dir", "methods", "foods", "levels", "trials", "seed",
                   "executor", "num_threads", "flush_every", "rollout_chunks")


@dataclass(frozen=True)
class EvaluationRefConfig:
    """Where the real objective gets its method from: the evaluation config and the files it needs.

    `method` is a guided built-in (grits*) or a controller the evaluation config registers whose
    class takes keyword arguments `rho` and `s`; any other is refused when the sweep starts
    (grits_lab/tune/grits_binding.py).
    `checkpoints` lists the files (policy and predictor checkpoints) that must exist before a
    sweep starts, so a missing file fails in the first second instead of in the first trial.
    `overrides` is merged onto the evaluation config as `grits-lab evaluate --override` merges a
    file (e.g. {"guidance": {"step": "normalized"}} tunes rho on the normalized guidance step);
    the trial's rho and s are set on top. It may change only how GRITS runs: the keys of
    NOT_OVERRIDABLE (the episode grid, which `validation` sets; where and how the episodes run)
    and `guidance.rho` / `guidance.s` (each trial's) fail on load.
    """

    config: str | None = None
    checkpoints: list[str] = field(default_factory=list)
    method: str = "grits"
    overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        wrong = sorted(set(self.overrides) & set(NOT_OVERRIDABLE))
        require(not wrong, "evaluation.overrides", wrong,
                "free of the episode grid and run settings (" + ", ".join(NOT_OVERRIDABLE) + "): `validation` sets the episodes")
        guidance = self.overrides.get("guidance") or {}
        require(isinstance(guidance, dict) and not {"rho", "s"} & set(guidance), "evaluation.overrides.guidance", guidance,
                "free of `rho` and `s`: each trial sets them")


@dataclass(frozen=True)
class SyntheticConfig:
    """Knobs of the synthetic stand-in objective (used only with `evaluator: synthetic`)."""

    seconds_per_episode: float = 0.0
    # Raise inside the objective when rho exceeds this value: exercises failed-trial handling.
    crash_above_rho: float | None = None

    def __post_init__(self) -> None:
        require(self.seconds_per_episode >= 0.0, "synthetic.seconds_per_episode", self.seconds_per_episode, ">= 0")


@dataclass(frozen=True)
class StudyConfig:
    """A sweep over GRITS's guidance weight rho and threshold s (paper Algorithm 1)."""

    retired_keys: ClassVar[dict[str, str]] = {"results_dir": "output_dir"}

    study_name: str
    n_trials: int
    validation: ValidationConfig
    rho: FloatRangeConfig = FloatRangeConfig(0.25, 10.0, log=True)
    s: IntRangeConfig = IntRangeConfig(6, 60)
    # The diffusion schedule's training steps T; s is a step on this scale (paper: T = 100, s = 30).
    train_timesteps: int = 100
    # Evaluated first, in this order (the paper's rho = 2.5, s = 30 by default).
    enqueue: list[GuidancePoint] = field(default_factory=lambda: [GuidancePoint(2.5, 30)])
    objective: ObjectiveConfig = ObjectiveConfig()
    sampler: SamplerConfig = SamplerConfig()
    # "grits": GRITS through the evaluation layer. "synthetic": a fast, deterministic stand-in
    # (not GRITS, not simulation) for testing the sweep machinery.
    evaluator: Literal["grits", "synthetic"] = "grits"
    evaluation: EvaluationRefConfig = EvaluationRefConfig()
    synthetic: SyntheticConfig = SyntheticConfig()
    # None: a journal file under output_dir/study_name/. Otherwise an RDB URL
    # (postgresql://user:password@host:port/db, sqlite:///path.db, mysql://...) or a journal file path.
    storage: str | None = None
    output_dir: str = "results/sweeps"  # the study's outputs go to output_dir/study_name/
    # A running trial writes a heartbeat this often; one silent for stale_after_s is taken as dead.
    heartbeat_s: float = 20.0
    stale_after_s: float = 120.0
    # Methods run once, as the evaluation config has them, on the same validation episodes (e.g.
    # [dp]: unguided Diffusion Policy), so each trial is read against them episode by episode
    # (grits_lab/tune/reference.py). Not part of the study's identity: adding one to a running
    # study keeps its trials.
    reference: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        require(bool(_NAME_RE.match(self.study_name)), "study_name", self.study_name,
                "letters, digits, '_', '.', '-' (it names a folder)")
        require(self.n_trials >= 1, "n_trials", self.n_trials, ">= 1")
        require(self.train_timesteps >= 1, "train_timesteps", self.train_timesteps, ">= 1")
        self.rho.check("rho")
        self.s.check("s", self.train_timesteps)
        for i, point in enumerate(self.enqueue):
            require(self.rho.contains(point.rho), f"enqueue[{i}].rho", point.rho,
                    f"inside rho's range [{self.rho.low}, {self.rho.high}]")
            require(self.s.contains(point.s), f"enqueue[{i}].s", point.s,
                    f"inside s's range [{self.s.low}, {self.s.high}] on its step {self.s.step}")
        if self.evaluator == "grits":
            require(bool(self.evaluation.config), "evaluation.config", self.evaluation.config,
                    "the path of an evaluation config when `evaluator: grits`")
        for i, method in enumerate(self.reference):
            require(isinstance(method, str) and bool(_NAME_RE.match(method)), f"reference[{i}]", method,
                    "a method name: letters, digits, '_', '.', '-' (it names a records file)")
        require(len(set(self.reference)) == len(self.reference), "reference", self.reference, "without repeats")
        if self.evaluator == "grits":
            require(self.evaluation.method not in self.reference, "reference", self.reference,
                    f"free of the tuned method `{self.evaluation.method}` (its trials are the sweep)")
        require(self.heartbeat_s > 0, "heartbeat_s", self.heartbeat_s, "> 0")
        require(self.stale_after_s > 2 * self.heartbeat_s, "stale_after_s", self.stale_after_s,
                f"more than twice heartbeat_s = {self.heartbeat_s}")

    @property
    def study_dir(self) -> Path:
        return Path(self.output_dir) / self.study_name

    def identity(self) -> str:
        """Fingerprint of what makes trials comparable: ranges, objective, episodes, evaluator."""
        v = self.validation
        return config_fingerprint({
            "rho": self.rho, "s": self.s, "train_timesteps": self.train_timesteps,
            "objective": self.objective,
            # The identity's recipe is fixed, not a reader of old names: the validation block is hashed
            # with its root seed as `root_seed`, as every stored study's identity (this protocol's
            # included) was taken; renaming it here would refuse them all.
            "validation": {"foods": v.foods, "levels": v.levels, "trials": v.trials, "root_seed": v.seed,
                           **({"first_trial": v.first_trial} if v.first_trial else {})},
            "evaluator": self.evaluator, "evaluation": self._evaluation_identity(),
        })

    def _evaluation_identity(self) -> dict[str, Any]:
        """The evaluation block as the identity hashes it: without `overrides` when there are none, as
        every stored study without overrides was hashed (the recipe is fixed)."""
        block = config_to_dict(self.evaluation)
        if not block["overrides"]:
            del block["overrides"]
        block["config"] = IDENTITY_CONFIG_PATHS.get(str(block["config"]), block["config"])
        return block

    def food_library(self) -> "FoodLibrary":
        """The food library the episodes come from: the evaluation config's (`evaluator: grits`), else the packaged one."""
        from grits_lab.sim.foods import load_foods

        if self.evaluator == "synthetic":
            return load_foods()
        from grits_lab.evaluation.evaluation_config import load_evaluation_config

        if not Path(str(self.evaluation.config)).is_file():
            raise InputError(f"evaluation config not found: {self.evaluation.config} (set `evaluation.config` in the sweep file)")
        return load_foods(load_evaluation_config(str(self.evaluation.config), self.evaluation.overrides).sim.foods_file)

    def episodes(self) -> list[EpisodeKey]:
        """The validation episodes (ConfigError naming `validation.foods` / `validation.levels` for a
        food or level the food library lacks)."""
        return self.validation.keys(self.food_library(), key_prefix="validation.")


def load_study_config(path: str | Path) -> StudyConfig:
    """Load and check a sweep file, its validation episodes included."""
    config = load_config(path, StudyConfig)
    try:
        config.episodes()
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    return config
