"""The one place where the sweep runs GRITS through the evaluation layer (`grits_lab.evaluation`).

The sweep sits above evaluation and calls it directly: the evaluation config is loaded once, the
validation episodes are evaluation `EpisodeKey`s (the sweep's validation block is an evaluation
episode grid with its own root seed, so no tuning episode is a test episode: `StudyConfig.episodes`),
and each trial runs `grits_lab.evaluation.evaluation_run.evaluate_guidance` with its (rho, s), getting one
evaluation record per episode (columns of grits_lab/records.py). Running GRITS goes through
`GritsEvaluator`; besides it, grits_lab.tune reads only the episode grid and the evaluation
config's food library from the evaluation layer.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from grits_lab.errors import ConfigError, InputError
from grits_lab.evaluation.evaluation_config import EvaluationConfig, load_evaluation_config
from grits_lab.evaluation.methods import METHODS, check_method_checkpoints, method_checkpoints
from grits_lab.evaluation.evaluation_run import evaluate_guidance
from grits_lab.runners.executor_config import check_reachable, cluster_address
from grits_lab.tune.study_config import StudyConfig


class GritsEvaluator:
    """`EpisodeEvaluator` that evaluates GRITS with guidance (rho, s) on the validation episodes."""

    label = "GRITS (grits_lab.evaluation)"

    def __init__(self, config: StudyConfig) -> None:
        ref = config.evaluation
        assert ref.config is not None  # StudyConfig requires it for `evaluator: grits`
        self._keys = config.episodes()  # InputError when the evaluation config is missing
        for path in ref.checkpoints:
            if not Path(path).is_file():
                raise InputError(f"checkpoint not found: {path} (listed in `evaluation.checkpoints`; train it first)")
        self._evaluation = load_evaluation_config(ref.config, ref.overrides)
        _check_against_evaluation(self._evaluation, ref.method)
        self._method = ref.method

    def __call__(self, rho: float, s: int, run_id: str) -> pd.DataFrame:
        return evaluate_guidance(self._evaluation, self._keys, rho=rho, s=s, method=self._method, run_id=run_id)

    def close(self) -> None:
        pass


def _check_against_evaluation(evaluation: EvaluationConfig, method: str) -> None:
    """Before any study exists: the method's checkpoints fit together and the Ray cluster it runs on answers."""
    if method not in METHODS:
        raise ConfigError(f"`evaluation.method` must be one of {', '.join(METHODS)}. Got {method!r}.")
    check_method_checkpoints(method, method_checkpoints(method, evaluation.checkpoints))
    check_reachable(cluster_address(evaluation.executor))
