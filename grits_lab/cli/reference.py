"""The command-line reference, docs/cli.md, generated from the parser (`python -m grits_lab.cli.reference`).

Every command and subcommand of `grits-lab` in the parser's order: its help line, its description,
its usage and a table of its arguments (retired spellings, hidden from `--help`, are left out), after
the flag conventions of grits_lab/cli/flags.py. tests/cli/test_reference.py fails when the
committed file differs from what the parser gives; write it again with

    python -m grits_lab.cli.reference > docs/cli.md
"""

from __future__ import annotations

import argparse
import os
import sys

from grits_lab.cli import build_parser
from grits_lab.cli import flags
from grits_lab.markdown import markdown_table

COMMAND = "python -m grits_lab.cli.reference > docs/cli.md"


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, str, argparse.ArgumentParser]]:
    """(name, help line, parser) of each subcommand of `parser`, in the order they were added."""
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
            out += [(name, helps.get(name, ""), sub) for name, sub in action.choices.items()]
    return out


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _arguments(parser: argparse.ArgumentParser) -> list[list[str]]:
    rows = []
    for action in parser._actions:
        if action.help == argparse.SUPPRESS or isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        if action.option_strings:
            takes = action.nargs != 0
            metavar = action.metavar or action.dest.upper()
            names = ", ".join(f"`{o}{' ' + metavar if takes else ''}`" for o in action.option_strings)
        else:
            names = f"`{action.metavar or action.dest}`"
        default = action.default if action.option_strings and action.default not in (None, False, [], argparse.SUPPRESS) else ""
        choices = f" One of: {', '.join(map(str, action.choices))}." if action.choices and not isinstance(action.choices, dict) else ""
        rows.append([names, _cell((action.help or "") % {"default": action.default} if "%(" in (action.help or "") else action.help or "")
                     + choices, f"`{default}`" if default != "" else ""])
    return rows


def _usage(parser: argparse.ArgumentParser) -> str:
    """The parser's usage on one line, whatever the terminal's width (argparse reads COLUMNS)."""
    width = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "10000"
    try:
        return " ".join(parser.format_usage().split()).removeprefix("usage: ")
    finally:
        if width is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = width


def _section(path: str, help_line: str, parser: argparse.ArgumentParser, level: int) -> list[str]:
    usage = _usage(parser)
    lines = [f"{'#' * level} `{path}`", ""]
    if help_line:
        lines += [_cell(help_line)[0].upper() + _cell(help_line)[1:] + ".", ""]
    if parser.description and parser.description != help_line:
        lines += [_cell(parser.description), ""]
    lines += ["```", usage, "```", ""]
    rows = _arguments(parser)
    if rows:
        lines += [markdown_table(["Argument", "Meaning", "Default"], rows, right=3), ""]
    for name, sub_help, sub in _subcommands(parser):
        lines += _section(f"{path} {name}", sub_help, sub, level + 1)
    return lines


def cli_reference(parser: argparse.ArgumentParser | None = None) -> str:
    """docs/cli.md's text: the flag conventions, then every command's section."""
    parser = parser or build_parser()
    conventions = flags.__doc__.split("\n\n")[1].strip()
    lines = ["# Command-line reference", "",
             f"Generated from the parser by `{COMMAND}`; do not edit by hand. "
             "`grits-lab COMMAND --help` prints the same.", "",
             "## One flag per meaning", "", conventions, "",
             "A retired spelling stops the command with one line naming its successor (docs/migration.md).", ""]
    for name, help_line, sub in _subcommands(parser):
        lines += _section(f"grits-lab {name}", help_line, sub, 2)
    return "\n".join(lines).rstrip() + "\n"


if __name__ == "__main__":
    sys.stdout.write(cli_reference())
