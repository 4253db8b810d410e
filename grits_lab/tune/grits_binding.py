"""The one place where the sweep runs a guided method through the evaluation layer (`grits_lab.evaluation`).

The sweep sits above evaluation and calls it directly: the evaluation config is loaded once, the
validation episodes are evaluation `EpisodeKey`s (the sweep's validation block is an evaluation
episode grid with its own root seed, so no tuning episode is a test episode: `StudyConfig.episodes`),
and each trial runs `grits_lab.evaluation.evaluation_run.evaluate_guidance` with its (rho, s), getting one
evaluation record per episode (columns of grits_lab/records.py). Running the method goes through
`GritsEvaluator`; besides it, grits_lab.tune reads only the episode grid and the evaluation
config's food library from the evaluation layer.

`evaluation.method` is a guided built-in (grits, grits_raw, grits_pointnet2, grits_horizon) or a controller the
evaluation config registers (`custom_methods`, or an entry point) whose class takes keyword
arguments `rho` and `s` (grits_lab/evaluation/custom_methods.py); any other method is refused
before the study exists, in one line naming what it lacks (`methods.guidance_gap`).

One pool per sweep process: the evaluator makes the evaluation config's executor (a Ray pool) at
its first trial and hands it to every trial after, so each worker builds its simulator and loads
the checkpoints once (the runner's `WorkerContext` keeps them) instead of once per trial; the
checkpoint files are resolved and hashed once too. `close` (the sweep calls it at the end, on
Ctrl-C and on errors) shuts the pool down; a trial that raises closes it as well, so no episode
of a broken trial is left in flight for the next one, which starts a fresh pool.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from grits_lab.errors import ConfigError, InputError
from grits_lab.evaluation.evaluation_config import EvaluationConfig, load_evaluation_config
from grits_lab.evaluation.methods import METHODS, check_method_checkpoints, guidance_gap, method_checkpoints, method_spec
from grits_lab.evaluation.evaluation_run import checkpoint_digests, evaluate_guidance, evaluate_keys
from grits_lab.runners import Executor, make_executor
from grits_lab.runners.executor_config import check_reachable, cluster_address
from grits_lab.tune.study_config import StudyConfig


class GritsEvaluator:
    """`EpisodeEvaluator` that evaluates `evaluation.method` (GRITS, or a registered guided
    controller) with guidance (rho, s) on the validation episodes."""

    label = "GRITS (grits_lab.evaluation)"

    @classmethod
    def label_for(cls, method: str) -> str:
        """What the outputs say evaluated the trials: GRITS for a built-in, never for a lab's controller."""
        return cls.label if method in METHODS else f"registered controller {method} (grits_lab.evaluation)"

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
        self.label = self.label_for(ref.method)
        self._paths = method_checkpoints(ref.method, self._evaluation.checkpoints)
        self._reference_paths = {m: _checked_reference(self._evaluation, m) for m in config.reference}
        self._digests = checkpoint_digests({ref.method: self._paths, **self._reference_paths})
        self._executor: Executor | None = None

    def __call__(self, rho: float, s: int, run_id: str) -> pd.DataFrame:
        return self._on_pool(lambda executor: evaluate_guidance(
            self._evaluation, self._keys, rho=rho, s=s, method=self._method, run_id=run_id,
            executor=executor, paths=self._paths, digests=self._digests))

    def reference(self, method: str, run_id: str) -> pd.DataFrame:
        """One record per validation episode of reference `method` (one of the sweep's `reference`),
        as the evaluation config has it, on the trials' pool."""
        return self._on_pool(lambda executor: evaluate_keys(
            self._evaluation, self._keys, method, run_id=run_id, executor=executor,
            paths=self._reference_paths[method], digests=self._digests))

    def _on_pool(self, run):
        if self._executor is None:
            self._executor = make_executor(self._evaluation.executor)
        try:
            return run(self._executor)
        except BaseException:
            self.close()  # episodes of this run may still be in flight: the next run gets a fresh pool
            raise

    def close(self) -> None:
        """Shut the pool down (idempotent)."""
        executor, self._executor = self._executor, None
        if executor is not None:
            executor.close()


def _checked_reference(evaluation: EvaluationConfig, method: str) -> dict[str, str]:
    """The checkpoints of reference `method`, checked before any study exists (ConfigError naming
    `reference` for a method the evaluation config cannot run)."""
    try:
        method_spec(method, evaluation)
    except KeyError:
        raise ConfigError(f"`reference`: {method} is no method: neither built-in ({', '.join(METHODS)}) nor registered "
                          "(`custom_methods` of the evaluation config, or a `grits_lab.methods` entry point)") from None
    paths = method_checkpoints(method, evaluation.checkpoints)
    check_method_checkpoints(method, paths)
    return paths


def _check_against_evaluation(evaluation: EvaluationConfig, method: str) -> None:
    """Before any study exists: the method takes guidance (rho, s), its checkpoints fit together and
    the Ray cluster it runs on answers."""
    gap = guidance_gap(method, evaluation)
    if gap is not None:
        raise ConfigError(f"`evaluation.method`: {method} {gap}")
    check_method_checkpoints(method, method_checkpoints(method, evaluation.checkpoints))  # each trial's s: the study's `s` range
    check_reachable(cluster_address(evaluation.executor))
