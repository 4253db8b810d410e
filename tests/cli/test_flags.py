"""One flag per meaning: `--level`, `--output-dir`, `--address`, `--restart` and one name per kind of
seed; each retired spelling stops the command with one line naming the new one; `--help` lists the
commands in the workflow's order."""

from __future__ import annotations

import argparse

import pytest

from grits_lab.cli import build_parser, main

ROLLOUT = ["rollout", "--food", "sago", "--level", "low", "--expert"]

# (command line with a retired spelling, the spelling the error names)
RETIRED = [
    (["rollout", "--food", "sago", "--quantity", "low", "--episode-seed", "0", "--expert"], "--quantity", "--level"),
    (ROLLOUT + ["--seed", "0"], "--seed", "--episode-seed"),
    (["scene", "--seed", "4"], "--seed", "--episode-seed"),
    (["foods", "--seed", "1"], "--seed", "--bowl-seed"),
    (["collect", "c.yaml", "--seed", "1000"], "--seed", "--root-seed"),
    (["compare-predictors", "a.yaml", "--held-out", "h", "--seed", "3"], "--seed", "--bootstrap-seed"),
    (["collect", "c.yaml", "--output", "d"], "--output", "--output-dir"),
    (["report", "run", "--out", "d"], "--out", "--output-dir"),
    (["compare-predictors", "a.yaml", "--held-out", "h", "--out", "d"], "--out", "--output-dir"),
    (["evaluate", "c.yaml", "--fresh"], "--fresh", "--restart"),
    (["train", "policy", "c.yaml", "--fresh"], "--fresh", "--restart"),
    (["train", "bc", "c.yaml", "--fresh"], "--fresh", "--restart"),
]


def _parse(argv: list[str]) -> argparse.Namespace:
    return build_parser().parse_args(argv)


@pytest.mark.parametrize("argv, old, new", RETIRED, ids=lambda v: " ".join(v[:2]) if isinstance(v, list) else v)
def test_a_retired_spelling_fails_in_one_line_naming_the_new_one(argv, old, new, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"grits-lab: error: {old} is retired; use {new}") and err.count("\n") == 1
    assert "docs/migration.md" in err


def test_each_seed_has_its_own_name_and_every_writer_and_ray_command_its_flag(capsys):
    assert _parse(ROLLOUT + ["--episode-seed", "3"]).episode_seed == 3
    assert _parse(["scene", "--episode-seed", "4"]).episode_seed == 4
    assert _parse(["foods"]).bowl_seed == 0 and _parse(["foods", "--bowl-seed", "2"]).bowl_seed == 2
    assert _parse(["collect", "c.yaml", "--root-seed", "1000"]).root_seed == 1000
    assert _parse(["compare-predictors", "a.yaml", "--held-out", "h", "--bootstrap-seed", "5"]).bootstrap_seed == 5
    for argv in (["collect", "c.yaml"], ["train", "policy", "c.yaml"], ["train", "bc", "c.yaml"], ["train", "predictor", "c.yaml"],
                 ["evaluate", "c.yaml"], ["report", "run"], ["compare-predictors", "a.yaml", "--held-out", "h"]):
        assert _parse([*argv, "--output-dir", "d"]).output_dir == "d", argv
    for argv in (["collect", "c.yaml"], ["evaluate", "c.yaml"], ["sweep", "s.yaml"], ["pipeline", "p.yaml"]):
        assert _parse([*argv, "--address", "10.0.0.1:6379"]).address == "10.0.0.1:6379", argv
    assert _parse(["evaluate", "c.yaml", "--restart"]).restart is True
    assert _parse(["evaluate", "c.yaml"]).restart is False
    assert capsys.readouterr().err == ""


def test_train_output_dir_overrides_the_configs(tmp_path, capsys):
    from grits_lab.cli.train_commands import _writing_to
    from grits_lab.policies.diffusion.training_diffusion import load_train_config

    config = load_train_config("experiments/policy_cpu.yaml")
    assert _writing_to(config, _parse(["train", "policy", "c.yaml", "--output-dir", str(tmp_path)])).output_dir == str(tmp_path)


def test_retired_spellings_are_hidden_from_help(capsys):
    for argv in (["rollout", "--help"], ["collect", "--help"], ["report", "--help"], ["evaluate", "--help"],
                 ["train", "policy", "--help"], ["compare-predictors", "--help"], ["foods", "--help"], ["scene", "--help"]):
        with pytest.raises(SystemExit):
            _parse(argv)
        text = capsys.readouterr().out
        for old in ("--quantity", "--fresh", "--out ", "--output ", "--seed "):
            assert old not in text, (argv, old)


def test_help_lists_the_commands_in_workflow_order_and_names_the_first_command(capsys):
    with pytest.raises(SystemExit):
        _parse(["--help"])
    text = capsys.readouterr().out
    workflow = ["foods", "scene", "rollout", "collect", "dataset", "train", "compare-predictors", "evaluate", "replay",
                "sweep", "report", "results", "pipeline"]
    listed = [line.split()[0] for line in text.split("COMMAND")[-1].splitlines() if line.startswith("    ") and not line.startswith("     ")]
    assert [c for c in listed if c in workflow] == workflow
    assert "first run: grits-lab pipeline experiments/quickstart.yaml" in text
