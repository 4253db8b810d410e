"""Typed configuration of an evaluation run: methods, checkpoints, guidance, foods x levels x trials, task stages.

An evaluation config is one YAML file (experiments/evaluate*.yaml). Everything that changes an
episode's outcome is in it (and so in the run directory's config.yaml); the executor section
only decides where episodes run. The sweep layer overrides `guidance` with `{rho, s}`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from grits_lab.config import config_from_dict, load_yaml, merge_mappings, require
from grits_lab.sampling.guidance import GuidanceConfig, PostHocConfig
from grits_lab.errors import ConfigError
from grits_lab.evaluation.custom_methods import CustomMethodConfig
from grits_lab.evaluation.grid import EpisodeGrid
from grits_lab.perception.composite import CloudConfig
from grits_lab.policies.control import ScoopSettings
from grits_lab.runners.executor_config import ExecutorConfig
from grits_lab.sim.sim_config import SimConfig
from grits_lab.task.transfer_settings import TransferSettings


@dataclass
class CheckpointPaths:
    """Trained models the methods load; a method whose checkpoint is null cannot be evaluated."""

    policy: str | None = None  # diffusion policy (dp, dp_post, grits*)
    predictor: str | None = None  # spillage predictor, composite cloud + DP3 (grits, dp_post)
    predictor_raw: str | None = None  # trained on raw camera clouds (grits_raw)
    predictor_pointnet2: str | None = None  # PointNet++ encoder (grits_pointnet2)
    predictor_horizon: str | None = None  # trained on the horizon label of a carry dataset (grits_horizon)
    bc: str | None = None  # behavior cloning (bc)
    demos: str | None = None  # demonstration dataset: SCONE's scoop prior (mean demonstration)



@dataclass
class RuleBasedSettings:
    """The rule-based baseline (SPEC): centre, measure the food height, rotate, dig 5 cm, fixed scoop."""

    dig_depth: float = 0.05
    entry_pitch_deg: float = 35.0  # spoon tip down while digging
    drag: float = 0.054  # metres of the scooping stroke along the spoon's x, centred on the bowl
    lift_height: float = 0.09  # above the rim at the end
    steps_per_segment: int = 8


@dataclass
class SconeSettings:
    """SCONE-style active perception: a vertical probe measures surface height and resistance."""

    probe_depth: float = 0.03  # metres the spoon's tip is pushed below the first contact
    probe_step: float = 0.004  # metres per action while probing
    contact_force: float = 0.05  # newtons on the spoon that count as touching the food
    reference_resistance: float = 0.5  # N per cm; the scoop's depth is scaled by ref / measured
    min_depth_scale: float = 0.5
    max_depth_scale: float = 1.3


@dataclass
class EvaluationConfig(EpisodeGrid):
    """One evaluation run: methods x the episode grid (foods x levels x trials; default the paper's
    10 unseen foods, every level, 5 trials, root seed 0), with the same seeds for every method."""

    run_id: str = "evaluate"
    output_dir: str = "results/evaluate"
    methods: list[str] = field(default_factory=lambda: ["grits", "dp"])
    checkpoints: CheckpointPaths = field(default_factory=CheckpointPaths)
    guidance: GuidanceConfig = field(default_factory=GuidanceConfig)  # Algorithm 1: rho = 2.5, s = 30, detached x0 gradient
    posthoc: PostHocConfig = field(default_factory=PostHocConfig)  # Diffusion Policy (Post.): authors' code, 6 steps
    scoop: ScoopSettings = field(default_factory=ScoopSettings)
    transfer: TransferSettings = field(default_factory=TransferSettings)
    rule_based: RuleBasedSettings = field(default_factory=RuleBasedSettings)
    scone: SconeSettings = field(default_factory=SconeSettings)
    sim: SimConfig = field(default_factory=SimConfig)
    cloud: CloudConfig = field(default_factory=CloudConfig)
    num_threads: int = 1  # torch threads per worker
    flush_every: int = 4  # write the records file after this many finished episodes
    # Also write every episode's scoop chunks (cloud at the chunk's start, its actions, whether
    # it spilled) as a spillage-kind dataset per method under <output_dir>/rollout_chunks/, the
    # held-out set on which `grits-lab compare-predictors --held-out` scores predictors on what the
    # policy really does.
    rollout_chunks: bool = False
    # Controllers a lab brings (grits_lab/evaluation/custom_methods.py): name -> the class and its options.
    custom_methods: dict[str, CustomMethodConfig] = field(default_factory=dict)
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)

    def __post_init__(self) -> None:
        from grits_lab.evaluation.custom_methods import controller_class, registered_methods
        from grits_lab.evaluation.methods import METHODS

        super().__post_init__()
        require(bool(self.run_id.strip()), "run_id", self.run_id, "a non-empty name")
        require(len(self.methods) >= 1, "methods", self.methods, "a non-empty list")
        for name in self.custom_methods:
            require(name not in METHODS, "custom_methods", name, "a name no built-in method has")
        custom = registered_methods(self.custom_methods)
        for m in self.methods:
            require(m in METHODS or m in custom, "methods", m, f"one of {', '.join([*METHODS, *custom])}")
            if m in custom:
                controller_class(m, custom[m])  # imported now: a wrong name fails at load
        require(len(set(self.methods)) == len(self.methods), "methods", self.methods, "without repeats")
        require(self.num_threads >= 1, "num_threads", self.num_threads, "at least 1")
        require(self.flush_every >= 1, "flush_every", self.flush_every, "at least 1")
        self.transfer.require_time_step_fits(self.sim, "transfer.time_step")


def load_evaluation_config(path: str | Path, overrides: dict[str, Any] | None = None) -> EvaluationConfig:
    """Load an evaluation YAML, with `overrides` (e.g. {"guidance": {"rho": 1.0, "s": 24}}) merged in."""
    data = load_yaml(path)
    if overrides:
        data = merge_mappings(data, overrides)
    try:
        return config_from_dict(EvaluationConfig, without_retired_keys(data))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


# Keys the scoop block held before its perturbations moved to a hook (grits_lab/policies/control.py
# `ScoopHook`), with the value that meant "off". Run directories written before then store them in
# config.yaml; at that value they are dropped, so those runs still load, resume and replay.
RETIRED_SCOOP_KEYS: dict[str, object] = {"action_offset": 0.0, "action_offset_draw": 0, "branch_plan": None, "branch_draw": 0}


def without_retired_keys(data: dict[str, Any]) -> dict[str, Any]:
    """`data` (an evaluation config's mapping) less the retired `scoop` keys at their "off" value;
    ConfigError naming the key when one is set: that perturbation is a study's hook now
    (`python -m studies.outcome_sensitivity`)."""
    scoop = data.get("scoop")
    if not isinstance(scoop, dict) or not set(scoop) & set(RETIRED_SCOOP_KEYS):
        return data
    for key, off in RETIRED_SCOOP_KEYS.items():
        if key in scoop and scoop[key] != off:
            raise ConfigError(f"`scoop.{key}` is no longer an evaluation setting: the nudge and the branches are a "
                              f"scoop hook (`python -m studies.outcome_sensitivity --help`); remove the key")
    return {**data, "scoop": {k: v for k, v in scoop.items() if k not in RETIRED_SCOOP_KEYS}}
