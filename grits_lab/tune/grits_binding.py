"""The one place where the sweep binds to the GRITS evaluation layer (`grits_lab.evaluation`).

The sweep sits above evaluation and calls it directly: the evaluation config is loaded once, the
validation episodes become evaluation `EpisodeKey`s (seeds from the sweep's own root, so no tuning
episode is a test episode), and each trial runs `grits_lab.evaluation.run.evaluate_guidance` with
its (rho, s), getting one evaluation record per episode (columns of grits_lab/records.py).
Everything the sweep needs from evaluation goes through `GritsEvaluator`; nothing else in
grits_lab.tune imports the evaluation layer.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from grits_lab.errors import ConfigError, InputError
from grits_lab.evaluation.config import EvaluationConfig, load_evaluation_config
from grits_lab.evaluation.methods import METHODS, check_method_checkpoints, method_checkpoints
from grits_lab.evaluation.run import EpisodeKey, evaluate_guidance
from grits_lab.runners.config import check_reachable, cluster_address
from grits_lab.tune.config import StudyConfig


class GritsEvaluator:
    """`EpisodeEvaluator` that evaluates GRITS with guidance (rho, s) on the validation episodes."""

    label = "GRITS (grits_lab.evaluation)"

    def __init__(self, config: StudyConfig) -> None:
        ref = config.evaluation
        assert ref.config is not None  # StudyConfig requires it for `evaluator: grits`
        if not Path(ref.config).is_file():
            raise InputError(f"evaluation config not found: {ref.config} (set `evaluation.config` in the sweep file)")
        for path in ref.checkpoints:
            if not Path(path).is_file():
                raise InputError(f"checkpoint not found: {path} (listed in `evaluation.checkpoints`; train it first)")
        self._evaluation = load_evaluation_config(ref.config)
        self._keys = _validation_keys(config, self._evaluation, ref.method)
        self._method = ref.method

    def __call__(self, rho: float, s: int, run_id: str) -> pd.DataFrame:
        return evaluate_guidance(self._evaluation, self._keys, rho=rho, s=s, method=self._method, run_id=run_id)

    def close(self) -> None:
        pass


def _validation_keys(config: StudyConfig, evaluation: EvaluationConfig, method: str) -> list[EpisodeKey]:
    """Before any study exists: the validation episodes are episodes of the evaluation config's
    food library, the method's checkpoints fit together, and the Ray cluster it runs on answers.
    Returns the validation episodes as evaluation keys."""
    from grits_lab.sim.foods import load_foods

    library = load_foods(evaluation.sim.foods_file)
    config.validation.check_names(library)
    if method not in METHODS:
        raise ConfigError(f"`evaluation.method` must be one of {', '.join(METHODS)}. Got {method!r}.")
    check_method_checkpoints(method, method_checkpoints(method, evaluation.checkpoints))
    check_reachable(cluster_address(evaluation.executor))
    return [EpisodeKey(e.food, e.level, e.index, e.seed, library.get(e.food).split) for e in config.validation.episodes()]
