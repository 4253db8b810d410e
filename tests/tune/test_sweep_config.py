"""Sweep files are validated on load: bad ranges and defaults fail with one line naming the key."""

from __future__ import annotations

import pytest

from grits_lab.errors import ConfigError
from grits_lab.tune.study_config import load_study_config
from tests.tune.sweep_helpers import REPO


@pytest.mark.parametrize("name", ["grits_quick", "grits_paper", "synthetic_standin"])
def test_repository_sweep_files_load(name):
    config = load_study_config(REPO / "sweeps" / f"{name}.yaml")
    assert config.study_name == name
    assert (config.enqueue[0].rho, config.enqueue[0].s) == (2.5, 30)  # the paper's defaults run first
    assert config.rho.contains(2.5) and config.s.contains(30)


@pytest.mark.parametrize(
    "overrides, key",
    [
        ({"rho": {"low": 3.0, "high": 1.0}}, "rho.high"),
        ({"rho": {"low": 0.0, "high": 5.0, "log": True}}, "rho.low"),
        ({"rho": {"low": -1.0, "high": 5.0, "log": False}}, "rho.low"),
        ({"s": {"low": 10, "high": 150, "step": 1}}, "s.high"),
        ({"s": {"low": 40, "high": 40, "step": 1}}, "s.high"),
        ({"s": {"low": 0, "high": 90, "step": 7}}, "s.step"),
        ({"enqueue": [{"rho": 20.0, "s": 30}]}, "enqueue[0].rho"),
        ({"enqueue": [{"rho": 2.5, "s": 31}]}, "enqueue[0].s"),
        ({"n_trials": 0}, "n_trials"),
        ({"objective": {"max_spillage": 1.5}}, "objective.max_spillage"),
        ({"evaluator": "grits"}, "evaluation.config"),
        ({"study_name": "a b/c"}, "study_name"),
        ({"rho": {"low": 0.5, "high": 8.0, "lg": True}}, "rho.lg"),
        ({"validation": {"trials": 10**9}}, "validation.trials"),
        ({"validation": {"first_trial": 10**21}}, "validation.first_trial"),
        ({"rho": {"low": 0.5, "high": float("inf"), "log": True}}, "rho.high"),
    ],
)
def test_invalid_sweep_files_are_rejected_naming_the_key(sweep_file, overrides, key):
    with pytest.raises(ConfigError) as info:
        load_study_config(sweep_file(**overrides))
    message = str(info.value)
    assert f"`{key}`" in message and "\n" not in message


def test_validation_episodes_have_seeds_derived_from_their_identity(sweep_file):
    a = load_study_config(sweep_file()).episodes()
    b = load_study_config(sweep_file()).episodes()
    assert a == b and len(a) == 2 * 2 * 2
    assert len({e.seed for e in a}) == len(a)
    other = load_study_config(sweep_file(validation={"seed": 12})).episodes()
    assert {e.seed for e in other}.isdisjoint({e.seed for e in a})


@pytest.mark.parametrize("validation, key, name", [
    ({"levels": ["low", "enormous"]}, "validation.levels", "enormous"),
    ({"foods": ["soybeans", "unobtainium"]}, "validation.foods", "unobtainium"),
])
def test_a_validation_food_or_level_the_library_lacks_fails_at_load_naming_the_key(sweep_file, validation, key, name):
    path = sweep_file(validation=validation)
    with pytest.raises(ConfigError) as info:
        load_study_config(path)
    message = str(info.value)
    assert message.startswith(f"{path}: `{key}`") and repr(name) in message and "\n" not in message


def test_the_validation_block_is_checked_by_the_evaluations_episode_grid(sweep_file):
    from grits_lab.evaluation.grid import EpisodeGrid

    config = load_study_config(sweep_file())
    assert isinstance(config.validation, EpisodeGrid)
    for validation, key in [({"trials": 0}, "validation.trials"), ({"levels": ["low", "low"]}, "validation.levels"),
                            ({"foods": []}, "validation.foods"), ({"root_seed": 3}, "validation.root_seed")]:
        with pytest.raises(ConfigError, match=f"`{key}`"):
            load_study_config(sweep_file(validation=validation))


# Digests of [[food, level, trial, seed], ...] and study identities before the validation block
# became an episode grid: its episodes, their seeds and existing studies must not change.
SHIPPED_EPISODES = {
    "grits_cpu": (20, "5d2806b57e171b49", "25d72b44589cfd3d"),
    "grits_cpu_normalized": (20, "5d2806b57e171b49", "a2531b9be33b233d"),
    "grits_paper": (50, "48430c570614e2a0", "33355baaa34cf9b4"),
    "grits_quick": (4, "32f285648b1b6d72", "145d59ced4e0bd92"),  # remade as the quickstart's sweep: a new study
    "synthetic_standin": (24, "b9291626d2bf9833", "2d9396727413733a"),
}


@pytest.mark.parametrize("name", sorted(SHIPPED_EPISODES))
def test_shipped_sweeps_keep_their_episodes_seeds_and_study_identity(name):
    import hashlib
    import json

    config = load_study_config(REPO / "sweeps" / f"{name}.yaml")
    rows = [[e.food, e.level, e.trial, e.seed] for e in config.episodes()]
    count, digest, identity = SHIPPED_EPISODES[name]
    assert len(rows) == count
    assert hashlib.sha256(json.dumps(rows).encode()).hexdigest()[:16] == digest
    assert config.identity() == identity


def test_evaluation_overrides_reach_the_trials_evaluation_config_and_the_study_identity(sweep_file, monkeypatch):
    from grits_lab.tune import grits_binding

    # the checkpoint and cluster checks need trained models; what is checked here is the config
    monkeypatch.setattr(grits_binding, "_check_against_evaluation", lambda evaluation, method: None)
    monkeypatch.setattr(grits_binding, "method_checkpoints", lambda method, checkpoints: {})
    evaluation = {"config": str(REPO / "experiments" / "evaluate_cpu.yaml"), "checkpoints": [], "method": "grits"}
    plain = load_study_config(sweep_file(evaluator="grits", evaluation=evaluation))
    normalized = load_study_config(sweep_file(evaluator="grits", evaluation={
        **evaluation, "overrides": {"guidance": {"step": "normalized"}, "transfer": {"max_joint_step": 0.3}}}))
    base = grits_binding.GritsEvaluator(plain)._evaluation
    loaded = grits_binding.GritsEvaluator(normalized)._evaluation
    assert (base.guidance.step, base.transfer.max_joint_step) == ("gradient", 0.5)
    assert (loaded.guidance.step, loaded.transfer.max_joint_step) == ("normalized", 0.3)
    assert loaded.guidance.gradient == base.guidance.gradient and loaded.foods == base.foods  # the rest is the file's
    assert plain.identity() != normalized.identity()  # a study tuned on another step is another study


@pytest.mark.parametrize("overrides, key", [
    ({"foods": ["penne"]}, "evaluation.overrides"),
    ({"executor": {"workers": 4}}, "evaluation.overrides"),
    ({"guidance": {"rho": 1.0}}, "evaluation.overrides.guidance"),
    ({"guidance": {"step": "normalized", "s": 30}}, "evaluation.overrides.guidance"),
])
def test_overrides_of_the_episodes_run_settings_or_the_tuned_parameters_are_refused(sweep_file, overrides, key):
    with pytest.raises(ConfigError) as info:
        load_study_config(sweep_file(evaluation={"overrides": overrides}))
    assert f"`{key}`" in str(info.value) and "\n" not in str(info.value)


def test_a_bad_evaluation_override_fails_on_load_naming_the_key(sweep_file):
    path = sweep_file(evaluator="grits", evaluation={
        "config": str(REPO / "experiments" / "evaluate_cpu.yaml"), "overrides": {"guidance": {"stepp": "normalized"}}})
    with pytest.raises(ConfigError) as info:
        load_study_config(path)
    assert "`guidance.stepp`" in str(info.value) and "\n" not in str(info.value)


def test_the_normalized_step_sweep_tunes_rho_on_that_step_from_its_median_paper_step():
    from grits_lab.evaluation.evaluation_config import load_evaluation_config

    config = load_study_config(REPO / "sweeps" / "grits_cpu_normalized.yaml")
    assert config.evaluation.overrides == {"guidance": {"step": "normalized"}}
    assert load_evaluation_config(config.evaluation.config, config.evaluation.overrides).guidance.step == "normalized"
    assert (config.enqueue[0].rho, config.enqueue[0].s) == (0.07, 30)
    cpu = load_study_config(REPO / "sweeps" / "grits_cpu.yaml")
    assert config.episodes() == cpu.episodes()  # the same validation episodes as the gradient-step sweep
