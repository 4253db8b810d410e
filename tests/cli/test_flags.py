"""One flag per meaning: `--level`, `--output-dir`, `--restart`; each old spelling still parses to the
same arguments and prints exactly one deprecation line to stderr."""

from __future__ import annotations

import argparse

import pytest

from grits_lab.cli import build_parser, main
from grits_lab.cli.flags import DeprecatedFlag, add_flag

ROLLOUT = ["rollout", "--food", "sago", "--seed", "0", "--expert"]

# (command line with the old spelling, the same with the new one)
RENAMED = [
    (ROLLOUT + ["--quantity", "low"], ROLLOUT + ["--level", "low"]),
    (["collect", "c.yaml", "--output", "d"], ["collect", "c.yaml", "--output-dir", "d"]),
    (["report", "run", "--out", "d"], ["report", "run", "--output-dir", "d"]),
    (["evaluate", "c.yaml", "--fresh"], ["evaluate", "c.yaml", "--restart"]),
    (["train", "policy", "c.yaml", "--fresh"], ["train", "policy", "c.yaml", "--restart"]),
    (["train", "bc", "c.yaml", "--fresh"], ["train", "bc", "c.yaml", "--restart"]),
]


def _parse(argv: list[str]) -> argparse.Namespace:
    return build_parser().parse_args(argv)


@pytest.mark.parametrize("old, new", RENAMED, ids=lambda argv: " ".join(argv[:2]))
def test_an_old_spelling_parses_like_the_new_one_and_warns_once(old, new, capsys):
    assert vars(_parse(new)) == vars(_parse(new)) and capsys.readouterr().err == ""
    assert vars(_parse(old)) == vars(_parse(new))
    (old_flag,) = set(old) - set(new)
    (new_flag,) = set(new) - set(old)
    assert capsys.readouterr().err == f"grits-lab: {old_flag} is deprecated; use {new_flag}\n"


def test_an_old_spelling_given_twice_still_warns_once(capsys):
    args = _parse(["report", "run", "--out", "a", "--out", "b"])
    assert args.output_dir == "b"
    assert capsys.readouterr().err.count("deprecated") == 1


def test_the_new_flags_parse_without_a_warning(capsys):
    assert _parse(ROLLOUT + ["--level", "high"]).level == "high"
    assert _parse(["collect", "c.yaml", "--output-dir", "d"]).output_dir == "d"
    assert _parse(["report", "run", "--output-dir", "d"]).output_dir == "d"
    assert _parse(["evaluate", "c.yaml", "--restart"]).restart is True
    assert _parse(["evaluate", "c.yaml"]).restart is False
    assert _parse(["train", "predictor", "c.yaml", "--restart", "--output-dir", "d"]).restart is True
    assert _parse(["compare-predictors", "a.yaml", "--eval", "h", "--output-dir", "d"]).output_dir == "d"
    assert capsys.readouterr().err == ""


def test_compare_predictors_keeps_out_as_a_deprecated_exact_directory(capsys):
    args = _parse(["compare-predictors", "a.yaml", "--eval", "h", "--out", "cmp"])
    assert args.out == "cmp" and args.output_dir is None
    assert capsys.readouterr().err == ("grits-lab: --out is deprecated; use --output-dir "
                                       "(the comparison goes to OUTPUT_DIR/comparison_<dataset>)\n")


def test_old_spellings_are_hidden_from_help(capsys):
    for argv in (["rollout", "--help"], ["collect", "--help"], ["report", "--help"], ["evaluate", "--help"],
                 ["train", "policy", "--help"], ["compare-predictors", "--help"]):
        with pytest.raises(SystemExit):
            _parse(argv)
        text = capsys.readouterr().out
        for old in ("--quantity", "--fresh", "--out ", "--output "):
            assert old not in text, (argv, old)


def test_a_required_flag_is_satisfied_by_either_spelling_but_not_by_both(capsys):
    with pytest.raises(SystemExit):
        main(["rollout", "--food", "sago", "--seed", "0", "--expert"])
    assert "--level is required" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        _parse(ROLLOUT + ["--level", "low", "--quantity", "high"])
    assert "not allowed with argument --level" in capsys.readouterr().err


def test_the_helper_copies_nargs_and_type_of_the_new_flag(capsys):
    parser = argparse.ArgumentParser()
    add_flag(parser, "--stages", deprecated=("--stage",), nargs="+", type=int, default=[])
    assert parser.parse_args(["--stage", "1", "2"]).stages == [1, 2]
    assert parser.parse_args([]).stages == []
    assert any(isinstance(a, DeprecatedFlag) and a.type is int and a.nargs == "+" for a in parser._actions)
    assert capsys.readouterr().err.count("\n") == 1
