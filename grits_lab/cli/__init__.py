"""The `grits-lab` command: parses arguments and hands each subcommand to its handler.

The top of the package's layering: every other package is imported from here, never the other
way round. Each command group has one module here (`<group>_commands.py`) exposing
`register(subparsers)`, which adds its subcommands and sets `handler` to a function taking the
parsed arguments and returning an exit code. Heavy imports (torch, ray, pybullet) happen inside
the handlers so that `--help` and bad-input errors are fast. Errors a user can fix (GritsError)
become one line and exit code 2.
"""

from __future__ import annotations

import argparse
import sys

from grits_lab import __version__
from grits_lab.cli import (
    compare_commands,
    data_commands,
    evaluate_commands,
    pipeline_commands,
    report_commands,
    results_commands,
    sim_commands,
    sweep_commands,
    train_commands,
)
from grits_lab.errors import GritsError

# In the order of the workflow, as `grits-lab --help` and the README list them: the world, data,
# training, evaluation, tuning, the report, the results pages, and the pipeline that runs them all.
COMMAND_GROUPS = (
    sim_commands,
    data_commands,
    train_commands,
    compare_commands,
    evaluate_commands,
    sweep_commands,
    report_commands,
    results_commands,
    pipeline_commands,
)

EPILOG = """first run: grits-lab pipeline experiments/quickstart.yaml (every stage at a small size, resumable)
flags that were renamed: docs/migration.md"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="grits-lab",
        description="Spillage-aware guided diffusion for robot food scooping, in PyBullet.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"grits-lab {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for group in COMMAND_GROUPS:
        group.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    return run_command(build_parser(), argv)


def run_command(parser: argparse.ArgumentParser, argv: list[str] | None = None) -> int:
    """Parse `argv` with `parser` and run the chosen handler (`handler` default): a GritsError is one
    line and exit code 2, an interrupt exit code 130. Also the entry of a study's `__main__`."""
    try:
        args = parser.parse_args(argv)
    except GritsError as exc:  # a retired flag (grits_lab/cli/flags.py)
        print(f"grits-lab: error: {exc}", file=sys.stderr)
        return 2
    handler = getattr(args, "handler", None)
    if handler is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(handler(args) or 0)
    except GritsError as exc:
        print(f"grits-lab: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("grits-lab: interrupted; finished work is kept and the job resumes when run again", file=sys.stderr)
        return 130
