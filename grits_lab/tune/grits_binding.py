"""The one place where the sweep binds to the GRITS evaluation layer (`grits_lab.evaluation`).

Contract with the evaluation layer: `grits_lab.evaluation.evaluate_guidance(config_path,
episodes, guidance, method, run_id) -> pandas.DataFrame` runs `method` (GRITS) as configured by
the evaluation config at `config_path`, with its guidance section overridden by
`guidance = {"rho": float, "s": int}`, on `episodes` (dicts with food, level, trial, seed), and
returns one evaluation record per episode (columns of grits_lab/records.py). Everything the
sweep needs from evaluation goes through `GritsEvaluator`; nothing else in grits_lab.tune
imports the evaluation layer.
"""

from __future__ import annotations

import importlib
from dataclasses import asdict
from pathlib import Path

import pandas as pd

from grits_lab.errors import ConfigError, InputError
from grits_lab.tune.config import StudyConfig

EVALUATION_MODULE = "grits_lab.evaluation"
ENTRY_POINT = "evaluate_guidance"


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
        try:
            module = importlib.import_module(EVALUATION_MODULE)
        except ModuleNotFoundError as exc:
            if exc.name is None or not EVALUATION_MODULE.startswith(exc.name):
                raise
            raise ConfigError(
                f"`evaluator: grits` needs the evaluation layer {EVALUATION_MODULE}, which this "
                f"installation lacks; `evaluator: synthetic` runs the sweep on its stand-in objective"
            ) from None
        evaluate = getattr(module, ENTRY_POINT, None)
        if not callable(evaluate):
            raise ConfigError(f"{EVALUATION_MODULE} has no `{ENTRY_POINT}` function; the sweep cannot evaluate GRITS")
        _check_against_evaluation(config, Path(ref.config), ref.method)
        self._evaluate = evaluate
        self._config_path = Path(ref.config)
        self._method = ref.method
        self._episodes = [asdict(e) for e in config.validation.episodes()]

    def __call__(self, rho: float, s: int, run_id: str) -> pd.DataFrame:
        return self._evaluate(
            config_path=self._config_path,
            episodes=self._episodes,
            guidance={"rho": float(rho), "s": int(s)},
            method=self._method,
            run_id=run_id,
        )

    def close(self) -> None:
        pass


def _check_against_evaluation(config: StudyConfig, evaluation_config: Path, method: str) -> None:
    """Before any study exists: the validation episodes are episodes of the evaluation config's
    food library, the method's checkpoints fit together, and the Ray cluster it runs on answers."""
    from grits_lab.config import config_from_dict
    from grits_lab.evaluation.config import load_evaluation_config
    from grits_lab.evaluation.methods import METHODS, check_method_checkpoints, method_checkpoints
    from grits_lab.runners.config import check_reachable, cluster_address
    from grits_lab.sim import SimConfig
    from grits_lab.sim.foods import load_foods

    evaluation = load_evaluation_config(evaluation_config)
    config.validation.check_names(load_foods(config_from_dict(SimConfig, evaluation.sim, "sim").foods_file))
    if method not in METHODS:
        raise ConfigError(f"`evaluation.method` must be one of {', '.join(METHODS)}. Got {method!r}.")
    check_method_checkpoints(method, method_checkpoints(method, evaluation.checkpoints))
    check_reachable(cluster_address(evaluation.executor))
