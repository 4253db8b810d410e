"""`grits-lab train policy CONFIG` and `grits-lab train bc CONFIG`: train or resume a policy that
learns from demonstrations, from an experiment YAML (both run grits_lab/policies/demo_training.py)."""

from __future__ import annotations

import argparse
import importlib

from grits_lab.io import to_json

# subcommand -> (help, example config, module, loader, trainer)
TRAINERS = {
    "policy": ("train the diffusion policy on demonstrations (resumes from the last checkpoint)", "experiments/policy_cpu.yaml",
               "grits_lab.policies.diffusion.training", "load_train_config", "train_policy"),
    "bc": ("train the behavior-cloning baseline on demonstrations (resumes)", "experiments/bc_cpu.yaml",
           "grits_lab.policies.bc.training", "load_bc_config", "train_bc"),
}


def register(subparsers: argparse._SubParsersAction) -> None:
    for name, (help_text, example, *_) in TRAINERS.items():
        parser = subparsers.add_parser(name, help=help_text)
        parser.add_argument("config", help=f"experiment YAML, e.g. {example}")
        parser.add_argument("--max-steps", type=int, default=None, help="stop at this step instead of the config's max_steps")
        parser.add_argument("--fresh", action="store_true", help="ignore an existing checkpoint and start over")
        parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
        parser.set_defaults(handler=_train, trainer=name)


def _train(args: argparse.Namespace) -> int:
    from grits_lab.errors import InputError

    if args.max_steps is not None and args.max_steps < 1:
        raise InputError(f"--max-steps must be at least 1. Got {args.max_steps}.")
    _, _, module_name, loader, trainer = TRAINERS[args.trainer]
    module = importlib.import_module(module_name)
    config = getattr(module, loader)(args.config)
    extra = {}
    if args.trainer == "policy":  # scoops during training are played in the simulator, from above the policy layer
        from grits_lab.evaluation.rollouts import ScoopRollouts

        extra["rollouts"] = ScoopRollouts
    summary = getattr(module, trainer)(config, max_steps=args.max_steps, progress=not args.no_progress, fresh=args.fresh, **extra)
    print(to_json(summary))
    return 0
