"""Evaluation of every method on the whole task (scoop -> transfer -> pour): registry, episodes, runs, sweep entry point."""

from grits_lab.evaluation.carry import carry_to_target
from grits_lab.evaluation.evaluation_config import EvaluationConfig, load_evaluation_config
from grits_lab.evaluation.evaluation_run import episode_keys, evaluate, evaluate_file, evaluate_guidance
from grits_lab.evaluation.grid import EpisodeGrid, EpisodeKey
from grits_lab.evaluation.methods import METHODS, MethodSpec

__all__ = [
    "METHODS",
    "EpisodeGrid",
    "EpisodeKey",
    "EvaluationConfig",
    "MethodSpec",
    "carry_to_target",
    "episode_keys",
    "evaluate",
    "evaluate_file",
    "evaluate_guidance",
    "load_evaluation_config",
]
