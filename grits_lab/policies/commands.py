"""`grits-lab train policy CONFIG`: train or resume the diffusion policy from an experiment YAML."""

from __future__ import annotations

import argparse
import json


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("policy", help="train the diffusion policy on demonstrations (resumes from the last checkpoint)")
    parser.add_argument("config", help="experiment YAML, e.g. experiments/policy_cpu.yaml")
    parser.add_argument("--max-steps", type=int, default=None, help="stop at this step instead of the config's max_steps")
    parser.add_argument("--fresh", action="store_true", help="ignore an existing checkpoint and start over")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.set_defaults(handler=_train)


def _train(args: argparse.Namespace) -> int:
    from grits_lab.errors import InputError
    from grits_lab.policies.diffusion.training import load_train_config, train_policy

    if args.max_steps is not None and args.max_steps < 1:
        raise InputError(f"--max-steps must be at least 1. Got {args.max_steps}.")
    config = load_train_config(args.config)
    summary = train_policy(config, max_steps=args.max_steps, progress=not args.no_progress, fresh=args.fresh)
    print(json.dumps(summary, indent=2))
    return 0
