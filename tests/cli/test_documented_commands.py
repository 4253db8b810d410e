"""Every `grits-lab ...` command the README and the user guide show parses with today's parser: a
renamed or retired flag in the docs fails here, not in a user's shell."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from grits_lab.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
# docs/cli.md is the parser's own usage text (tests/cli/test_reference.py), not commands to run.
PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").glob("*.md") if p.name != "cli.md"), *sorted((ROOT / "studies").glob("*/README.md")),
         ROOT / "experiments" / "README.md"]
FENCE = re.compile(r"^```")


def documented_commands(text: str) -> list[tuple[int, str]]:
    """(line, command) of every `grits-lab` line inside a fenced code block, continuations joined."""
    found, inside, pending, start = [], False, "", 0
    for number, line in enumerate(text.splitlines(), 1):
        if FENCE.match(line.strip()):
            inside, pending = not inside, ""
            continue
        if not inside:
            continue
        if pending:
            pending += " " + line.strip()
        elif re.match(r"^\s*(\S+=\S+\s+)*grits-lab\s", line):
            pending, start = line.strip(), number
        if pending and pending.endswith("\\"):
            pending = pending[:-1]
            continue
        if pending:
            found.append((start, pending))
            pending = ""
    return found


CASES = [(page, number, command) for page in PAGES if page.is_file()
         for number, command in documented_commands(page.read_text())]


def test_the_pages_show_commands():
    assert len(CASES) >= 20


@pytest.mark.parametrize("page, number, command", CASES, ids=[f"{p.relative_to(ROOT)}:{n}" for p, n, _ in CASES])
def test_a_documented_command_parses(page, number, command, capsys):
    words = shlex.split(command, comments=True)
    words = words[[w.startswith("grits-lab") for w in words].index(True) + 1:]  # after any VAR=value prefix
    words = [w for w in words if w not in ("&&", "|")] if "&&" not in words else words[:words.index("&&")]
    try:
        build_parser().parse_args(words)
    except SystemExit as stop:
        pytest.fail(f"{page.relative_to(ROOT)}:{number}: `{command}` does not parse (exit {stop.code}): "
                    f"{capsys.readouterr().err.strip().splitlines()[-1:]}")
