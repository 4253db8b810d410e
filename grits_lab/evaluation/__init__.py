"""Evaluation of every method on the whole task (scoop -> transfer -> pour): registry, episodes, runs, sweep entry point."""

from grits_lab.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "config": ["EvaluationConfig", "load_evaluation_config"],
    "methods": ["METHODS", "MethodSpec"],
    "grid": ["EpisodeGrid", "EpisodeKey"],
    "run": ["episode_keys", "evaluate", "evaluate_file", "evaluate_guidance"],
})
