"""Typed configuration of an evaluation run: methods, checkpoints, guidance, foods x levels x trials, task stages.

An evaluation config is one YAML file (experiments/evaluate*.yaml). Everything that changes an
episode's outcome is in it (and so in the run directory's config.yaml); the executor section
only decides where episodes run. The sweep layer overrides `guidance` with `{rho, s}`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from grits_lab.config import config_from_dict, load_yaml, merge_mappings, require
from grits_lab.sampling.guidance import GuidanceConfig, PostHocConfig
from grits_lab.errors import ConfigError
from grits_lab.evaluation.custom_methods import CustomMethodConfig
from grits_lab.evaluation.grid import EpisodeGrid
from grits_lab.perception.composite import CloudConfig
from grits_lab.policies.control import ScoopSettings
from grits_lab.runners.executor_config import ExecutorConfig
from grits_lab.sim.sim_config import SimConfig


@dataclass
class CheckpointPaths:
    """Trained models the methods load; a method whose checkpoint is null cannot be evaluated."""

    policy: str | None = None  # diffusion policy (dp, dp_post, grits*)
    predictor: str | None = None  # spillage predictor, composite cloud + DP3 (grits, dp_post)
    predictor_raw: str | None = None  # trained on raw camera clouds (grits_raw)
    predictor_pointnet2: str | None = None  # PointNet++ encoder (grits_pointnet2)
    bc: str | None = None  # behavior cloning (bc)
    demos: str | None = None  # demonstration dataset: SCONE's scoop prior (mean demonstration)



@dataclass
class TransferSettings:
    """Stages 2 and 3: locate the target bowl from the cameras, move there without collision, pour
    (docs/evaluation.md, "The task, stage by stage", gives each value's reason and source)."""

    enabled: bool = True
    clearance: float = 0.06  # metres the spoon keeps above the bowls' rims and the table on the way
    # Peak speed of the spoon while transferring (m/s; commands at the control rate). With the
    # min-jerk profile the mean is 0.53x and the peak acceleration about 0.1 m/s^2 on a 30-40 cm carry.
    max_speed: float = 0.12
    # "min_jerk": every straight segment of the lift and carry, and the pour's roll, goes from rest
    # to rest on the minimum-jerk profile (what a motion planner's time-parameterization gives a
    # robot); "constant": equal steps, full speed from the first action.
    profile: Literal["min_jerk", "constant"] = "min_jerk"
    level_steps: int = 10  # actions over which the lift turns the spoon level (one sudden turn swings the arm)
    # "radial": on the way across, turn the spoon to point away from the robot's base over the
    # target (the arm's natural posture there); "keep": keep the scoop's heading, which twists the
    # wrist to its limit for targets off to the side.
    heading: Literal["radial", "keep"] = "radial"
    # Spoon centre above the target bowl's rim when pouring (m; negative: below it). At 1 cm the
    # rolled spoon's lower edge is about 8 mm inside the bowl, 3 cm from its wall.
    pour_height: float = 0.01
    pour_angle_deg: float = 120.0  # roll of the spoon about its x axis to empty it
    # Actions of the roll: 3 s, a mean 40 deg/s; at the spoon's edge (2 cm) the roll's peak
    # accelerations are under 0.05 m/s^2, so food slides out under gravity rather than being flung.
    pour_steps: int = 30
    settle_steps: int = 15  # actions holding still after the pour before counting
    # Before moving, check the path and pour on the arm's kinematic copy (grits_lab/sim/env.py
    # `check_path`). With `slow_to_limits`, every action asking a joint to move faster than the
    # Panda's velocity limit (robot.PANDA_MAX_JOINT_VELOCITY) is slowed (cut into more actions, at
    # most `max_slowdown` per planned action); a motion that still exceeds it is a change of arm
    # posture and fails. Without it, a motion fails when a joint steps more than `max_joint_step`
    # rad in one action. A motion that fails, or holds an unreachable pose, is replaced by the
    # first alternative that passes: the lift with `alternative_level_steps` and the level spoon
    # turned by `alternative_level_yaw_deg`, the pour from `alternative_pour_heights` and moved
    # `alternative_pour_offsets` metres away from the robot's base (negative: towards it).
    # At most `max_checks` options (about 1 s each on one core, more when slowed).
    reach_check: bool = True
    # The IK's null-space pull towards the arm's rest posture in these stages. Off: the arm follows
    # the path with the least joint motion; on (as in the scoop, and in the transfer before its
    # min-jerk version), an arm far from its rest posture swings shoulder against upper arm in
    # one action however slowly it moves (measured 0.34 rad in 0.1 s, 1.6x the Panda's limit).
    rest_pull: bool = False
    slow_to_limits: bool = True
    max_slowdown: int = 8
    max_joint_step: float = 0.5
    alternative_level_steps: list[int] = field(default_factory=lambda: [30])
    alternative_level_yaw_deg: list[float] = field(default_factory=lambda: [-60.0, 60.0, -90.0, 90.0])
    alternative_pour_heights: list[float] = field(default_factory=lambda: [0.03, 0.05])
    alternative_pour_offsets: list[float] = field(default_factory=lambda: [0.03, -0.03])
    max_checks: int = 16

    def __post_init__(self) -> None:
        require(self.clearance > 0, "transfer.clearance", self.clearance, "positive")
        require(self.max_joint_step > 0, "transfer.max_joint_step", self.max_joint_step, "positive (rad per action)")
        require(self.max_slowdown >= 1, "transfer.max_slowdown", self.max_slowdown, "at least 1")
        require(not self.slow_to_limits or self.reach_check, "transfer.slow_to_limits", self.slow_to_limits,
                "false when `transfer.reach_check` is false (slowing needs the arm's kinematic check)")
        require(self.max_checks >= 1, "transfer.max_checks", self.max_checks, "at least 1")
        require(all(int(n) >= 1 for n in self.alternative_level_steps), "transfer.alternative_level_steps",
                self.alternative_level_steps, "a list of integers >= 1")
        deep = "above -0.03 m (deeper, the rolled spoon meets the bowl's floor)"
        require(self.pour_height > -0.03, "transfer.pour_height", self.pour_height, deep)
        require(all(h > -0.03 for h in self.alternative_pour_heights), "transfer.alternative_pour_heights",
                self.alternative_pour_heights, f"a list of heights {deep}")
        require(self.max_speed > 0, "transfer.max_speed", self.max_speed, "positive")
        require(self.pour_steps >= 1, "transfer.pour_steps", self.pour_steps, "at least 1")
        require(self.level_steps >= 1, "transfer.level_steps", self.level_steps, "at least 1")


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
    # held-out set on which `grits-lab compare-predictors --eval` scores predictors on what the
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


def load_evaluation_config(path: str | Path, overrides: dict[str, Any] | None = None) -> EvaluationConfig:
    """Load an evaluation YAML, with `overrides` (e.g. {"guidance": {"rho": 1.0, "s": 24}}) merged in."""
    data = load_yaml(path)
    if overrides:
        data = merge_mappings(data, overrides)
    try:
        return config_from_dict(EvaluationConfig, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
