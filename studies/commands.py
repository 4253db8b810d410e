"""A study's committed commands, read from its README and run in order (`python -m studies.<name> [--run]`).

A study README holds its commands in one fenced `bash` block under the heading `## Commands`:
one command a line (a line ending in a backslash continues), `#` comments kept out. Without
`--run` they are printed; with it each runs in turn from the repository's root, stopping at the
first that fails. The README is the one place the commands are written.
"""

from __future__ import annotations

import argparse
import re
import shlex
import subprocess
import sys
from pathlib import Path

from grits_lab.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"^## Commands\n.*?```bash\n(?P<body>.*?)```", re.S | re.M)


def study_commands(readme: Path) -> list[str]:
    """The commands of the README's `## Commands` block, continuation lines joined, comments dropped.
    InputError naming the README when it has no such block."""
    found = BLOCK.search(readme.read_text())
    if found is None:
        raise InputError(f"{readme}: no `## Commands` section with a ```bash block")
    joined = found["body"].replace("\\\n", " ")
    commands = []
    for line in joined.splitlines():
        line = line.split(" #")[0].strip() if not line.lstrip().startswith("#") else ""
        if line:
            commands.append(" ".join(line.split()))
    return commands


def main(study: str, argv: list[str] | None = None) -> int:
    """`python -m studies.<study> [--run]`: print (or run) the study's commands; the exit status of the first that fails."""
    parser = argparse.ArgumentParser(prog=f"python -m studies.{study}",
                                     description=f"The commands of studies/{study}/README.md, in order.")
    parser.add_argument("--run", action="store_true", help="run them one after another (stops at the first that fails)")
    args = parser.parse_args(argv)
    try:
        commands = study_commands(ROOT / "studies" / study / "README.md")
    except InputError as exc:
        print(f"grits-lab: error: {exc}", file=sys.stderr)
        return 2
    for command in commands:
        print(command, flush=True)
        if args.run:
            code = subprocess.run(["bash", "-c", command], cwd=ROOT).returncode
            if code:
                print(f"grits-lab: error: `{shlex.quote(command)}` exited {code}", file=sys.stderr)
                return code
    return 0
