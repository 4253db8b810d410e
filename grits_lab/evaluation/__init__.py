"""Evaluation of every method on the whole task (scoop -> transfer -> pour): registry, episodes, runs, sweep entry point."""

from grits_lab.evaluation.config import EvaluationConfig, GuidanceSettings, load_evaluation_config
from grits_lab.evaluation.methods import METHODS, MethodSpec
from grits_lab.evaluation.run import EpisodeKey, episode_keys, evaluate, evaluate_file, evaluate_guidance

__all__ = [
    "EpisodeKey",
    "EvaluationConfig",
    "GuidanceSettings",
    "METHODS",
    "MethodSpec",
    "episode_keys",
    "evaluate",
    "evaluate_file",
    "evaluate_guidance",
    "load_evaluation_config",
]
