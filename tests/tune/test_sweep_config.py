"""Sweep files are validated on load: bad ranges and defaults fail with one line naming the key."""

from __future__ import annotations

import pytest

from grits_lab.errors import ConfigError
from grits_lab.tune.config import load_study_config
from sweep_helpers import REPO


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
    ],
)
def test_invalid_sweep_files_are_rejected_naming_the_key(sweep_file, overrides, key):
    with pytest.raises(ConfigError) as info:
        load_study_config(sweep_file(**overrides))
    message = str(info.value)
    assert f"`{key}`" in message and "\n" not in message


def test_validation_episodes_have_seeds_derived_from_their_identity(sweep_file):
    a = load_study_config(sweep_file()).validation.episodes()
    b = load_study_config(sweep_file()).validation.episodes()
    assert a == b and len(a) == 2 * 2 * 2
    assert len({e.seed for e in a}) == len(a)
    other = load_study_config(sweep_file(validation={"root_seed": 12})).validation.episodes()
    assert {e.seed for e in other}.isdisjoint({e.seed for e in a})
