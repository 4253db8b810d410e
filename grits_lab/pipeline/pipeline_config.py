"""Pipeline config: which stage configs to run, what to override in them, and where outputs go.

A pipeline names the same experiment and sweep YAML files a user would run one by one, plus
per-stage overrides. The pipeline itself owns every path that links one stage to the next (the
demonstrations a policy trains on, the checkpoints an evaluation loads), so the stage files can
be shared between a laptop quickstart and a cluster run without editing paths by hand.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from grits_lab.config import config_from_dict, load_yaml, require
from grits_lab.errors import ConfigError

# Execution order; a stage runs only when it is configured.
STAGE_ORDER = (
    "demos",
    "spillage",
    "spillage_heldout",
    "spillage_carry",
    "policy",
    "bc",
    "predictor",
    "predictor_raw",
    "predictor_pointnet2",
    "predictor_horizon",
    "sweep",  # before the evaluation: its best (rho, s) is the evaluation's guidance
    "evaluate",
    "report",
)

# Stages whose outputs another stage reads.
UPSTREAM = {
    "spillage": ("demos",),
    "spillage_heldout": ("demos",),
    "spillage_carry": ("demos",),
    "policy": ("demos",),
    "bc": ("demos",),
    "predictor": ("spillage", "spillage_heldout"),
    "predictor_raw": ("spillage", "spillage_heldout"),
    "predictor_pointnet2": ("spillage", "spillage_heldout"),
    "predictor_horizon": ("spillage_carry",),
    "sweep": ("demos", "policy", "predictor"),
    "evaluate": ("demos", "policy", "bc", "predictor", "predictor_raw", "predictor_pointnet2", "predictor_horizon", "sweep"),
    "report": ("evaluate", "sweep"),
}


@dataclass
class StageConfig:
    """One stage: the YAML file to start from and the keys to override in it (nested mappings merge)."""

    config: str | None = None
    overrides: dict[str, Any] = field(default_factory=dict)


@dataclass
class PipelineConfig:
    name: str
    output_dir: str
    stages: dict[str, StageConfig]
    workers: int | None = None  # parallel sim workers for collection and evaluation; null: the stage's own
    address: str | None = None  # Ray cluster address for collection and evaluation; null: local Ray

    def __post_init__(self) -> None:
        require(bool(self.name), "name", self.name, "a non-empty string")
        require(self.workers is None or self.workers >= 1, "workers", self.workers, "at least 1 or null")
        unknown = sorted(set(self.stages) - set(STAGE_ORDER))
        if unknown:
            raise ConfigError(f"unknown stage `stages.{unknown[0]}`; stages: {', '.join(STAGE_ORDER)}")
        for name, stage in self.stages.items():
            if name != "report" and stage.config is None:
                raise ConfigError(f"`stages.{name}.config` must name a YAML file")
            if stage.config is not None and not Path(stage.config).is_file():
                raise ConfigError(f"`stages.{name}.config`: file not found: {stage.config}")
        for name in self.stages:
            for needed in _required_upstream(name):
                if needed not in self.stages:
                    raise ConfigError(f"stage `{name}` needs stage `{needed}`, which is not configured")

    def ordered_stages(self) -> list[str]:
        return [name for name in STAGE_ORDER if name in self.stages]


def _required_upstream(stage: str) -> tuple[str, ...]:
    """Upstream stages without which `stage` cannot run at all (others are used when present)."""
    return {
        "spillage": (),
        "spillage_heldout": ("spillage",),
        "policy": ("demos",),
        "bc": ("demos",),
        "predictor": ("spillage",),
        "predictor_raw": ("spillage",),
        "predictor_pointnet2": ("spillage",),
        "predictor_horizon": ("spillage_carry",),
        "evaluate": (),
        "sweep": ("evaluate", "policy", "predictor"),
        "report": ("evaluate",),
    }.get(stage, ())


def load_pipeline_config(path: str | Path) -> PipelineConfig:
    data = load_yaml(path)
    try:
        return config_from_dict(PipelineConfig, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
