"""`grits-lab collect CONFIG`, `grits-lab dataset info PATH` and `dataset export`: dataset generation, inspection, export."""

from __future__ import annotations

import argparse
from typing import Any

from grits_lab.cli import dataset_export
from grits_lab.cli.flags import NO_PROGRESS_HELP, retire
from grits_lab.io import to_json


def register(subparsers: Any) -> None:
    collect = subparsers.add_parser(
        "collect",
        help="generate a dataset (demonstrations or spillage trials) from an experiments/*.yaml config",
        description="Generate a dataset in parallel. Re-running the same command resumes an interrupted job.",
    )
    collect.add_argument("config", help="collection config, e.g. experiments/demos_quick.yaml")
    collect.add_argument("--output-dir", metavar="DIR", help="dataset directory (overrides `output_dir` in the config)")
    collect.add_argument("--root-seed", type=int, metavar="N",
                         help="root seed every episode's seed is derived from (overrides `seed:`; e.g. a held-out copy of a dataset)")
    collect.add_argument("--workers", type=int, help="number of parallel workers (overrides executor.workers)")
    collect.add_argument("--address", help="Ray cluster address (overrides executor.address and RAY_ADDRESS)")
    collect.add_argument("--serial", action="store_true", help="run in this process, without Ray")
    collect.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    retire(collect, "--output", "--output-dir")
    retire(collect, "--seed", "--root-seed")
    collect.set_defaults(handler=_collect)

    dataset = subparsers.add_parser("dataset", help="inspect and export datasets")
    dataset_sub = dataset.add_subparsers(dest="dataset_command", metavar="ACTION")
    info = dataset_sub.add_parser("info", help="counts by food, shape and label; size on disk")
    info.add_argument("path", help="dataset directory")
    info.add_argument("--json", action="store_true", help="print JSON instead of text")
    info.set_defaults(handler=_info)
    dataset_export.register(dataset_sub)
    dataset.set_defaults(handler=lambda args: (dataset.print_help(), 2)[1])


def _collect(args: argparse.Namespace) -> int:
    from grits_lab.collection.jobs import load_collect_config, run_collection

    config = load_collect_config(args.config)
    if args.output_dir:
        config.output_dir = args.output_dir
    if args.root_seed is not None:
        config.seed = args.root_seed
    if args.workers is not None:
        if args.workers < 1:
            from grits_lab.errors import InputError

            raise InputError(f"--workers must be at least 1. Got {args.workers}.")
        config.executor.workers = args.workers
    if args.address:
        config.executor.address = args.address
    if args.serial:
        config.executor.backend = "serial"
    carry = None
    if config.kind == "spillage" and config.exit.carries():  # the evaluation's transfer and pour end each trial
        from grits_lab.evaluation.carry import carry_to_target

        carry = carry_to_target
    summary = run_collection(config, progress=not args.no_progress, carry=carry)
    print(to_json(summary))
    return 0


def _info(args: argparse.Namespace) -> int:
    from grits_lab.data.info import dataset_summary, format_summary

    summary = dataset_summary(args.path)
    print(to_json(summary) if args.json else format_summary(summary))
    return 0
