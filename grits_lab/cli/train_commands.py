"""`grits-lab train policy|bc|predictor CONFIG`: train or resume the diffusion policy, the
behavior-cloning baseline (both learn from demonstrations, grits_lab/policies/demo_training.py)
or the spillage predictor (which can also score a checkpoint with --held-out)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

from grits_lab.cli.flags import NO_PROGRESS_HELP, retire
from grits_lab.io import to_json


def register(subparsers: argparse._SubParsersAction) -> None:
    train = subparsers.add_parser("train", help="train the diffusion policy, the behavior-cloning baseline or the spillage predictor")
    train_sub = train.add_subparsers(dest="train_target", metavar="WHAT")
    for name, help_text, example, handler in (
        ("policy", "train the diffusion policy on demonstrations (resumes from the last checkpoint)", "experiments/policy_cpu.yaml", _train_policy),
        ("bc", "train the behavior-cloning baseline on demonstrations (resumes)", "experiments/bc_cpu.yaml", _train_bc),
    ):
        parser = train_sub.add_parser(name, help=help_text)
        parser.add_argument("config", help=f"experiment YAML, e.g. {example}")
        parser.add_argument("--output-dir", metavar="DIR", help="run directory (overrides output_dir in the config)")
        parser.add_argument("--max-steps", type=int, default=None, help="stop at this step instead of the config's max_steps")
        parser.add_argument("--restart", action="store_true", help="ignore the run's existing checkpoint and start from step 0")
        parser.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
        retire(parser, "--fresh", "--restart")
        parser.set_defaults(handler=handler)
    _register_predictor(train_sub)
    train.set_defaults(handler=lambda args: _missing_subcommand(train))


def _missing_subcommand(parser: argparse.ArgumentParser) -> int:
    import sys

    parser.print_usage(sys.stderr)
    print(f"{parser.prog}: error: choose a subcommand", file=sys.stderr)
    return 2


def _check_max_steps(args: argparse.Namespace) -> None:
    from grits_lab.errors import InputError

    if args.max_steps is not None and args.max_steps < 1:
        raise InputError(f"--max-steps must be at least 1. Got {args.max_steps}.")


def _writing_to(config: Any, args: argparse.Namespace) -> Any:
    """`config` with `output_dir` from --output-dir when given."""
    if args.output_dir:
        config.output_dir = args.output_dir
    return config


def _print_summary(summary: dict[str, Any]) -> int:
    print(to_json(summary))
    return 0


def _train_policy(args: argparse.Namespace) -> int:
    _check_max_steps(args)
    from grits_lab.evaluation.rollouts import ScoopRollouts  # scoops during training, played in the simulator
    from grits_lab.policies.diffusion.training_diffusion import load_train_config, train_policy

    return _print_summary(train_policy(_writing_to(load_train_config(args.config), args), max_steps=args.max_steps,
                                       progress=not args.no_progress, restart=args.restart, rollouts=ScoopRollouts))


def _train_bc(args: argparse.Namespace) -> int:
    _check_max_steps(args)
    from grits_lab.policies.bc.training_bc import load_bc_config, train_bc

    return _print_summary(train_bc(_writing_to(load_bc_config(args.config), args), max_steps=args.max_steps,
                                   progress=not args.no_progress, restart=args.restart))


def _register_predictor(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "predictor",
        help="train the spillage predictor (or score a checkpoint with --held-out)",
        description="Train the spillage predictor on a spillage dataset; a rerun resumes after the last finished epoch.",
    )
    parser.add_argument("config", help="experiment YAML (e.g. experiments/predictor_cpu.yaml)")
    parser.add_argument("--dataset", nargs="+", metavar="DIR",
                        help="training dataset directory, or several trained on together (overrides data.dataset in the config)")
    parser.add_argument("--output-dir", metavar="DIR", help="where runs are written (overrides output_dir in the config)")
    parser.add_argument("--restart", action="store_true", help="discard the run's checkpoints and start from epoch 1")
    parser.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    parser.add_argument("--held-out", metavar="DATASET",
                        help="only score a checkpoint on every chunk of this held-out spillage dataset (no training)")
    parser.add_argument("--checkpoint", default="best", help="with --held-out: 'best', 'last' or a checkpoint path (default: best)")
    parser.add_argument("--label", choices=["chunk", "horizon"],
                        help="with --held-out: score against this label (default: data.label, the one the predictor trained on)")
    retire(parser, "--eval", "--held-out")
    parser.set_defaults(handler=_train_predictor)


def _train_predictor(args: argparse.Namespace) -> int:
    from grits_lab.config import load_config
    from grits_lab.io import write_json_atomic
    from grits_lab.spillage.predictor_config import PredictorConfig
    from grits_lab.spillage.predictor_training import run_dir

    config = load_config(args.config, PredictorConfig)
    if args.dataset:  # replace() checks the flag's values as the config's are checked
        config.data = dataclasses.replace(config.data, dataset=args.dataset[0] if len(args.dataset) == 1 else list(args.dataset))
    if args.output_dir:
        config.output_dir = args.output_dir
    if args.held_out is None:
        from grits_lab.spillage.predictor_training import train_predictor

        return _print_summary(train_predictor(config, restart=args.restart, progress=not args.no_progress))

    import torch

    from grits_lab.spillage.predictor_checkpoint import load_predictor
    from grits_lab.spillage.predictor_training import evaluate_predictor

    torch.set_num_threads(config.train.num_threads)
    path = run_dir(config) / f"{args.checkpoint}.pt" if args.checkpoint in ("best", "last") else Path(args.checkpoint)
    report = {"checkpoint": str(path), **evaluate_predictor(load_predictor(path), args.held_out, n_bins=config.train.ece_bins, label=args.label)}
    suffix = "" if report["label"] == "chunk" else f"_{report['label']}"
    write_json_atomic(run_dir(config) / f"eval_{Path(args.held_out).name}{suffix}.json", report)
    return _print_summary(report)
