"""The study's sampler, reseeded per trial so that seeded workers sharing a storage do not collide.

A sampler seeded once per process makes every worker started with the same seed draw the same
"random" points. `TrialSeededSampler` builds the configured sampler for each trial with the seed
derive_seed(seed, trial number): one worker reproduces the same study from the same seed, and
workers that share a study draw different points because they hold different trial numbers.
"""

from __future__ import annotations

import warnings
from typing import Any, Callable, Sequence

import optuna
from optuna.distributions import BaseDistribution
from optuna.samplers import BaseSampler
from optuna.trial import FrozenTrial, TrialState

from grits_lab.seeding import derive_seed
from grits_lab.tune.study_config import SamplerConfig

SPILLAGE_RATE_ATTR = "spillage_rate"


class TrialSeededSampler(BaseSampler):
    """Delegates to `factory(seed_for_trial)`, built once per trial number."""

    def __init__(self, factory: Callable[[int], BaseSampler], seed: int) -> None:
        self._factory = factory
        self._seed = seed
        self._number: int | None = None
        self._inner: BaseSampler | None = None

    def _for(self, trial: FrozenTrial) -> BaseSampler:
        if self._inner is None or self._number != trial.number:
            self._inner = self._factory(derive_seed(self._seed, "sampler", trial.number))
            self._number = trial.number
        return self._inner

    def infer_relative_search_space(self, study: optuna.Study, trial: FrozenTrial) -> dict[str, BaseDistribution]:
        return self._for(trial).infer_relative_search_space(study, trial)

    def sample_relative(self, study: optuna.Study, trial: FrozenTrial, search_space: dict[str, BaseDistribution]) -> dict[str, Any]:
        return self._for(trial).sample_relative(study, trial, search_space)

    def sample_independent(self, study: optuna.Study, trial: FrozenTrial, param_name: str, param_distribution: BaseDistribution) -> Any:
        return self._for(trial).sample_independent(study, trial, param_name, param_distribution)

    def before_trial(self, study: optuna.Study, trial: FrozenTrial) -> None:
        self._for(trial).before_trial(study, trial)

    def after_trial(self, study: optuna.Study, trial: FrozenTrial, state: TrialState, values: Sequence[float] | None) -> None:
        self._for(trial).after_trial(study, trial, state, values)

    def reseed_rng(self) -> None:
        self._inner = None


def build_sampler(config: SamplerConfig, max_spillage: float | None) -> TrialSeededSampler:
    """The configured sampler; with `max_spillage`, spillage_rate - max_spillage <= 0 is a constraint."""
    constraints = None
    if max_spillage is not None:
        def constraints(trial: FrozenTrial) -> Sequence[float]:
            # A trial that failed before it was scored is infeasible.
            return [float(trial.user_attrs.get(SPILLAGE_RATE_ATTR, 1.0)) - max_spillage]

    def factory(seed: int) -> BaseSampler:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            if config.name == "random":
                return optuna.samplers.RandomSampler(seed=seed)
            if config.name == "gp":
                return optuna.samplers.GPSampler(seed=seed, n_startup_trials=config.n_startup_trials,
                                                 constraints_func=constraints)
            return optuna.samplers.TPESampler(seed=seed, n_startup_trials=config.n_startup_trials,
                                              multivariate=True, constant_liar=True,
                                              constraints_func=constraints)

    return TrialSeededSampler(factory, config.seed)
