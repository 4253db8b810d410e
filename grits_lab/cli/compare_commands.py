"""`grits-lab compare-predictors CONFIG... --held-out DATASET...`: held-out table of trained predictors.
`grits-lab compare-runs BEFORE AFTER`: two evaluation runs on the same seeds, episode by episode."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from grits_lab.cli.flags import retire


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "compare-predictors",
        help="score trained spillage predictors on held-out datasets, with paired bootstrap intervals",
        description=(
            "Score the checkpoint of every predictor config on every chunk of DATASET (or of several) and write a table "
            "(AUROC, accuracy, ECE with 95 % intervals from resampling whole episodes, and each model's "
            "paired difference to the first config), ROC and reliability plots, and the per-chunk predictions. "
            "Chunks of several foods are also scored within food, and chunks are scored within food and position "
            "(the chunk's index in its episode); under the horizon label a no-model row, chunk_position, ranks "
            "earlier chunks higher (docs/predictor.md, \"Held-out comparison\")."
        ),
    )
    parser.add_argument("configs", nargs="+", metavar="CONFIG", help="predictor configs; the first is the reference")
    parser.add_argument("--held-out", nargs="+", metavar="DATASET", required=True,
                        help="held-out spillage dataset directory, or several scored as one set (each episode a bootstrap unit)")
    retire(parser, "--eval", "--held-out")
    retire(parser, "--branches", "`python -m studies.outcome_sensitivity branches RUN... --predictors CONFIG...`")
    add_predictor_arguments(parser)
    parser.set_defaults(handler=_run)

    runs = subparsers.add_parser(
        "compare-runs",
        help="two evaluation runs on the same seeds, episode by episode: equal scoops and paired outcome changes",
        description=(
            "Pair the episodes of two run directories by method, food, level and trial (their seeds must agree) and "
            "print, per method, how many scoops are equal and each outcome's count in both runs with the episodes "
            "that changed either way and an exact sign test on them (grits_lab/report/run_compare.py)."
        ),
    )
    runs.add_argument("before", metavar="BEFORE", help="run directory of `grits-lab evaluate` (the reference)")
    runs.add_argument("after", metavar="AFTER", help="run directory on the same seeds")
    runs.add_argument("--output-dir", metavar="DIR", help="also write comparison.csv and comparison.md there")
    retire(runs, "--ceiling", "`python -m studies.outcome_sensitivity compare BEFORE AFTER --declared`")
    runs.set_defaults(handler=_compare_runs)


def add_predictor_arguments(parser: argparse.ArgumentParser) -> None:
    """The scoring arguments of `compare-predictors` (--checkpoint, --output-dir, --bootstrap, --label,
    --bootstrap-seed), shared with a study's command that scores predictors (`predictor_checkpoints`)."""
    parser.add_argument("--checkpoint", default="best", choices=["best", "last"], help="which checkpoint of each run (default: best)")
    parser.add_argument("--output-dir", metavar="DIR",
                        help="where the runs are and the comparison is written, to OUTPUT_DIR/comparison_<dataset> "
                             "(overrides output_dir in every config; default: the first config's)")
    parser.add_argument("--bootstrap", type=int, default=2000, metavar="N", help="bootstrap resamples (default 2000)")
    parser.add_argument("--label", choices=["chunk", "horizon"],
                        help="score against this label of every chunk: chunk (the spilled count rose during the chunk) or "
                             "horizon (food spilled before the load was delivered); default: the one the predictors trained on")
    parser.add_argument("--bootstrap-seed", type=int, default=0, metavar="N", help="seed of the bootstrap resampling (default 0)")
    retire(parser, "--out", "--output-dir (the comparison goes to OUTPUT_DIR/comparison_<dataset>)")
    retire(parser, "--seed", "--bootstrap-seed")


def _compare_runs(args: argparse.Namespace) -> int:
    from grits_lab.io import check_writable_dir
    from grits_lab.report.run_compare import compare_run_dirs, write_comparison

    if args.output_dir:
        check_writable_dir(args.output_dir)  # before the comparison, not after it
    table, markdown = compare_run_dirs(args.before, args.after)
    print(markdown)
    if args.output_dir:
        print(f"written: {', '.join(str(f) for f in write_comparison(table, markdown, args.output_dir))}")
    return 0


def predictor_checkpoints(args: argparse.Namespace, config_paths: list[str]) -> tuple[dict[str, Path], list, str]:
    """({name: checkpoint}, the loaded configs, the label to score against) of the predictor configs,
    with the arguments of `add_predictor_arguments`; InputError on a missing checkpoint, a repeated
    name, labels that disagree without --label, or too few bootstrap resamples."""
    import torch

    from grits_lab.config import load_config
    from grits_lab.errors import InputError
    from grits_lab.spillage.predictor_config import PredictorConfig
    from grits_lab.spillage.predictor_training import run_dir

    if args.bootstrap < 100:
        raise InputError(f"--bootstrap must be at least 100 (got {args.bootstrap})")
    checkpoints: dict[str, Path] = {}
    configs = [load_config(path, PredictorConfig) for path in config_paths]
    for path, config in zip(config_paths, configs):
        if args.output_dir:
            config.output_dir = args.output_dir
        if config.name in checkpoints:
            raise InputError(f"two configs are named {config.name!r} ({path}); names label the rows")
        checkpoint = run_dir(config) / f"{args.checkpoint}.pt"
        if not checkpoint.is_file():
            raise InputError(f"{path}: no {args.checkpoint} checkpoint at {checkpoint}; train it first with `grits-lab train predictor {path}`")
        checkpoints[config.name] = checkpoint
    torch.set_num_threads(configs[0].train.num_threads)
    trained_on = {config.name: config.data.label for config in configs}
    if args.label is None and len(set(trained_on.values())) > 1:
        raise InputError(f"the predictors trained on different labels ({', '.join(f'{n}: {lb}' for n, lb in trained_on.items())}); "
                         "choose the one to score against with --label chunk or --label horizon")
    return checkpoints, configs, args.label or configs[0].data.label


def _run(args: argparse.Namespace) -> int:
    from grits_lab.io import check_writable_dir
    from grits_lab.spillage.compare import compare_predictions, comparison_markdown, predict_all, write_comparison

    checkpoints, configs, label = predictor_checkpoints(args, args.configs)
    out = Path(configs[0].output_dir) / f"comparison_{'+'.join(Path(d).name for d in args.held_out)}"
    if label != "chunk":  # scored against another label: its own table, beside the chunk label's
        out = out.with_name(f"{out.name}_{label}")
    check_writable_dir(out)  # before the predictions, not after them
    predictions = predict_all(checkpoints, args.held_out, label=label)
    comparison = compare_predictions(predictions, list(checkpoints), n_resamples=args.bootstrap, seed=args.bootstrap_seed, n_bins=configs[0].train.ece_bins, label=label)
    files = write_comparison(comparison, ", ".join(args.held_out), out)
    print(comparison_markdown(comparison, ", ".join(args.held_out)))
    print(f"written: {', '.join(str(f) for f in files)}")
    return 0
