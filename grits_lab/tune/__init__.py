"""Optuna sweeps over GRITS's guidance weight rho and threshold s: config, storage, study loop, outputs."""

from grits_lab.tune.study_config import StudyConfig, load_study_config
from grits_lab.tune.objective import EpisodeEvaluator, TrialMetrics, make_evaluator
from grits_lab.tune.outputs import best_trial, trials_frame, write_outputs
from grits_lab.tune.storage import open_storage
from grits_lab.tune.study import open_study, recover_stale_trials, run_trials

__all__ = [
    "EpisodeEvaluator",
    "StudyConfig",
    "TrialMetrics",
    "best_trial",
    "load_study_config",
    "make_evaluator",
    "open_storage",
    "open_study",
    "recover_stale_trials",
    "run_trials",
    "trials_frame",
    "write_outputs",
]
