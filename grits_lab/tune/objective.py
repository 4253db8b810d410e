"""From a trial's (rho, s) to objective values: evaluate the episodes, check the records, score them.

The study layer sees the evaluation only through `EpisodeEvaluator`: a callable
`(rho, s, run_id) -> DataFrame` of evaluation records (grits_lab/records.py), one row per
validation episode. Every trial is checked to cover exactly the configured episodes with their
derived seeds, so no two trials are compared on different episodes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Protocol

import pandas as pd

from grits_lab.errors import InputError
from grits_lab.evaluation.grid import EpisodeKey
from grits_lab.records import RECORD_COLUMNS, has_error
from grits_lab.tune.study_config import ObjectiveConfig, StudyConfig


class EpisodeEvaluator(Protocol):
    """Runs the validation episodes with guidance (rho, s) and returns one record per episode."""

    label: str

    def __call__(self, rho: float, s: int, run_id: str) -> pd.DataFrame: ...

    def reference(self, method: str, run_id: str) -> pd.DataFrame:
        """The validation episodes of a method the sweep is read against (`StudyConfig.reference`)."""
        ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class TrialMetrics:
    """Rates over one trial's episodes; errored episodes count as failures (never as successes)."""

    success_rate: float
    spillage_rate: float
    scoop_failure_rate: float
    n_episodes: int
    n_errors: int

    def as_attrs(self) -> dict[str, float | int]:
        return asdict(self)


def check_records(records: pd.DataFrame, episodes: list[EpisodeKey]) -> None:
    """Raise InputError unless `records` holds exactly one row per validation episode, same seeds."""
    missing = [c for c in RECORD_COLUMNS if c not in records.columns]
    if missing:
        raise InputError(f"evaluation records lack the columns {missing} (see grits_lab/records.py)")
    expected = {(e.food, e.level, e.trial, e.seed) for e in episodes}
    got = [(str(f), str(lv), int(t), int(sd)) for f, lv, t, sd in
           zip(records["food"], records["level"], records["trial"], records["seed"])]
    if len(got) != len(set(got)) or set(got) != expected:
        extra = sorted(set(got) - expected)[:3]
        lacking = sorted(expected - set(got))[:3]
        raise InputError(
            f"evaluation returned episodes that differ from the validation set "
            f"({len(got)} rows for {len(expected)} episodes; unexpected {extra}, missing {lacking})"
        )


def scored_outcomes(records: pd.DataFrame) -> pd.DataFrame:
    """Per episode (records' index), the outcomes as the sweep scores them: `task_success`,
    `spillage`, `scoop_failure`; an episode with an error is no success and a scoop failure."""
    errors = has_error(records["error"])
    return pd.DataFrame({
        "task_success": records["task_success"].astype(bool) & ~errors,
        "spillage": records["spillage"].astype(bool),
        "scoop_failure": records["scoop_failure"].astype(bool) | errors,
        "error": errors,
    })


def summarize_records(records: pd.DataFrame) -> TrialMetrics:
    scored = scored_outcomes(records)
    return TrialMetrics(
        success_rate=float(scored["task_success"].mean()),
        spillage_rate=float(scored["spillage"].mean()),
        scoop_failure_rate=float(scored["scoop_failure"].mean()),
        n_episodes=int(len(records)),
        n_errors=int(scored["error"].sum()),
    )


def objective_values(metrics: TrialMetrics, objective: ObjectiveConfig) -> list[float]:
    if objective.mode == "single":
        return [metrics.success_rate - objective.spillage_weight * metrics.spillage_rate]
    return [metrics.success_rate, metrics.spillage_rate]


def make_evaluator(config: StudyConfig) -> EpisodeEvaluator:
    """The configured evaluator; the GRITS binding is imported only when it is asked for."""
    if config.evaluator == "synthetic":
        from grits_lab.tune.synthetic import SyntheticEvaluator

        return SyntheticEvaluator(config.episodes(), config.synthetic, config.train_timesteps)
    from grits_lab.tune.grits_binding import GritsEvaluator

    return GritsEvaluator(config)
