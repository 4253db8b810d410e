"""`grits-lab train bc CONFIG`: train or resume the behavior-cloning baseline from an experiment YAML."""

from __future__ import annotations

import argparse
import json


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("bc", help="train the behavior-cloning baseline on demonstrations (resumes)")
    parser.add_argument("config", help="experiment YAML, e.g. experiments/bc_cpu.yaml")
    parser.add_argument("--max-steps", type=int, default=None, help="stop at this step instead of the config's max_steps")
    parser.add_argument("--fresh", action="store_true", help="ignore an existing checkpoint and start over")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.set_defaults(handler=_train)


def _train(args: argparse.Namespace) -> int:
    from grits_lab.errors import InputError
    from grits_lab.policies.bc.training import load_bc_config, train_bc

    if args.max_steps is not None and args.max_steps < 1:
        raise InputError(f"--max-steps must be at least 1. Got {args.max_steps}.")
    summary = train_bc(load_bc_config(args.config), max_steps=args.max_steps, progress=not args.no_progress, fresh=args.fresh)
    print(json.dumps(summary, indent=2))
    return 0
