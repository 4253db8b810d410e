"""`grits-lab train predictor`: train, resume or evaluate the spillage predictor from a YAML config."""

from __future__ import annotations

import argparse
from pathlib import Path

from grits_lab.io import to_json


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "predictor",
        help="train the spillage predictor (or score a checkpoint with --eval)",
        description="Train the spillage predictor on a spillage dataset; a rerun resumes after the last finished epoch.",
    )
    parser.add_argument("config", help="experiment YAML (e.g. experiments/predictor_cpu.yaml)")
    parser.add_argument("--dataset", help="training dataset directory (overrides data.dataset in the config)")
    parser.add_argument("--output-dir", help="where runs are written (overrides output_dir in the config)")
    parser.add_argument("--restart", action="store_true", help="discard the run's checkpoints and start from epoch 1")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar or per-epoch lines")
    parser.add_argument("--eval", metavar="DATASET", help="only score a checkpoint on every chunk of this (held-out) spillage dataset")
    parser.add_argument("--checkpoint", default="best", help="with --eval: 'best', 'last' or a checkpoint path (default: best)")
    parser.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from grits_lab.config import load_config
    from grits_lab.io import write_json_atomic
    from grits_lab.spillage.config import PredictorConfig
    from grits_lab.spillage.training import run_dir

    config = load_config(args.config, PredictorConfig)
    if args.dataset:
        config.data.dataset = args.dataset
    if args.output_dir:
        config.output_dir = args.output_dir
    if args.eval is None:
        from grits_lab.spillage.training import train_predictor

        result = train_predictor(config, restart=args.restart, progress=not args.no_progress)
        print(to_json(result))
        return 0

    import torch

    from grits_lab.spillage.checkpoint import load_predictor
    from grits_lab.spillage.training import evaluate_predictor

    torch.set_num_threads(config.train.num_threads)
    path = run_dir(config) / f"{args.checkpoint}.pt" if args.checkpoint in ("best", "last") else Path(args.checkpoint)
    report = {"checkpoint": str(path), **evaluate_predictor(load_predictor(path), args.eval, n_bins=config.train.ece_bins)}
    write_json_atomic(run_dir(config) / f"eval_{Path(args.eval).name}.json", report)
    print(to_json(report))
    return 0
