"""The `grits-lab` command: parses arguments and hands each subcommand to the module that owns it.

Each area of the package exposes `register(subparsers)` in its own `commands` module, which adds
its subcommands and sets `handler` to a function taking the parsed arguments and returning an
exit code. Heavy imports (torch, ray, pybullet) happen inside the handlers so that `--help` and
bad-input errors are fast. Errors a user can fix (GritsError) become one line and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from grits_lab import __version__
from grits_lab.errors import GritsError

# Modules that register top-level subcommands.
COMMAND_MODULES = [
    "grits_lab.pipeline.commands",
    "grits_lab.data.commands",
    "grits_lab.sim.commands",
    "grits_lab.tune.commands",
    "grits_lab.report.commands",
    "grits_lab.evaluation.commands",
    "grits_lab.spillage.compare_commands",
]

# Modules that register `grits-lab train <what>` subcommands.
TRAIN_MODULES = [
    "grits_lab.spillage.commands",
    "grits_lab.policies.commands",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="grits-lab",
        description="Spillage-aware guided diffusion for robot food scooping, in PyBullet.",
    )
    parser.add_argument("--version", action="version", version=f"grits-lab {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    if TRAIN_MODULES:
        train = subparsers.add_parser("train", help="train the diffusion policy or the spillage predictor")
        train_sub = train.add_subparsers(dest="train_target", metavar="WHAT")
        for name in TRAIN_MODULES:
            importlib.import_module(name).register(train_sub)
        train.set_defaults(handler=lambda args: _missing_subcommand(train))
    return parser


def _missing_subcommand(parser: argparse.ArgumentParser) -> int:
    parser.print_usage(sys.stderr)
    print(f"{parser.prog}: error: choose a subcommand", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
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


if __name__ == "__main__":
    sys.exit(main())
