"""docs/cli.md is the parser's own reference (grits_lab/cli/reference.py): regenerated, it is unchanged."""

from __future__ import annotations

from pathlib import Path

from grits_lab.cli import build_parser
from grits_lab.cli.reference import COMMAND, cli_reference

ROOT = Path(__file__).resolve().parents[2]


def test_the_committed_cli_reference_is_what_the_parser_generates():
    assert (ROOT / "docs" / "cli.md").read_text() == cli_reference(), f"docs/cli.md is stale: `{COMMAND}`"


def test_the_reference_holds_every_command_and_argument_and_no_retired_spelling():
    text = cli_reference()
    for name in ("evaluate", "train policy", "train bc", "train predictor", "compare-predictors", "results check", "pipeline"):
        assert f"`grits-lab {name}`" in text
    assert "`--held-out DATASET`" in text and "`--checkpoint KEY=PATH`" in text and "`--rerun STAGE`" in text
    tables = text.split("## `grits-lab foods`")[1]  # the conventions may name a retired spelling; no table does
    for retired in ("`--eval", "`--force", "`--videos", "`--branch-draw", "`--action-offset-draw", "`--fresh", "`--ceiling"):
        assert retired not in tables


def test_a_flag_added_to_the_parser_appears_in_the_reference_with_its_help():
    parser = build_parser()
    evaluate = next(a for a in parser._actions if a.dest == "command").choices["evaluate"]
    evaluate.add_argument("--new-flag", metavar="N", help="a flag no one documented by hand")
    assert "| `--new-flag N` | a flag no one documented by hand |" in cli_reference(parser)
