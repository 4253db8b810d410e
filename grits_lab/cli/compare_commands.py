"""`grits-lab compare-predictors CONFIG... --eval DATASET...`: held-out table of trained predictors.
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
            "earlier chunks higher (docs/predictor.md, \"Held-out comparison\"). With --branches instead of --eval, "
            "the chunks are those runs of one branch plan executed there, scored within each state, with how often "
            "the draws of a state disagree and how often each guide's pick spills (docs/predictor.md, \"Within one state\")."
        ),
    )
    parser.add_argument("configs", nargs="*", metavar="CONFIG",
                        help="predictor configs; the first is the reference (none with --branches: the draws' spread alone)")
    held_out = parser.add_mutually_exclusive_group(required=True)
    held_out.add_argument("--eval", nargs="+", metavar="DATASET",
                          help="held-out spillage dataset directory, or several scored as one set (each episode a bootstrap unit)")
    held_out.add_argument("--branches", nargs="+", metavar="RUN",
                          help="run directories of `grits-lab evaluate` with one scoop.branch_plan and different "
                               "scoop.branch_draw: score the chunk each executed at the branch plan, within each state")
    parser.add_argument("--method", default="dp", metavar="METHOD",
                        help="with --branches: whose rollout chunks to score (default dp)")
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
    runs.add_argument("--ceiling", action="store_true",
                      help="add the AUROC-ceiling table for runs that differ only by chance the records do not name "
                           "(e.g. CPU kernels, for records made before `cpu_kernels` was recorded)")
    runs.set_defaults(handler=_compare_runs)


def _compare_runs(args: argparse.Namespace) -> int:
    from grits_lab.io import check_writable_dir
    from grits_lab.report.run_compare import compare_run_dirs, write_comparison

    if args.output_dir:
        check_writable_dir(args.output_dir)  # before the comparison, not after it
    table, markdown = compare_run_dirs(args.before, args.after, ceiling=args.ceiling)
    print(markdown)
    if args.output_dir:
        print(f"written: {', '.join(str(f) for f in write_comparison(table, markdown, args.output_dir))}")
    return 0


BRANCH_RUNS_FILE = "branch_runs.json"  # the run directories a --branches comparison folder was written from


def _claim_branch_folder(out: Path, runs: list[Path]) -> list[str]:
    """The resolved run directories of a --branches comparison; InputError when `out` already holds
    the comparison of other runs of the same names (two studies' `draw0`, `draw1`): it is kept."""
    from grits_lab.errors import InputError

    listed = [str(p.resolve()) for p in runs]
    record = out / BRANCH_RUNS_FILE
    try:
        earlier = json.loads(record.read_text()).get("runs") if record.is_file() else None
    except (OSError, ValueError, AttributeError):
        earlier = None  # unreadable: as a folder written before the record existed
    if earlier is not None and earlier != listed:
        raise InputError(f"{out} holds the comparison of the runs {', '.join(map(str, earlier))}, not of "
                         f"{', '.join(listed)}; give another --output-dir to keep both")
    return listed


def _branches(args: argparse.Namespace, checkpoints: dict[str, Path], configs: list, label: str) -> int:
    """`compare-predictors --branches RUN...`: the comparison within states, the draws' spread and each guide's pick."""
    from grits_lab.io import ensure_writable_dir, write_json_atomic, write_text_atomic
    from grits_lab.report.branches import (SCOOP_ONLY_HORIZON, branch_markdown, branch_predictions, branch_runs, check_model_names,
                                           outcome_spread, selection)
    from grits_lab.spillage.compare import compare_predictions, comparison_markdown, write_comparison

    runs = branch_runs(args.branches, args.method)  # before any model runs
    check_model_names(list(checkpoints))
    from grits_lab.config import parse_yaml

    config_file = runs[0].path / "config.yaml"
    name = (parse_yaml(config_file.read_text(), config_file) or {}).get("run_id", runs[0].path.name)
    root = Path(args.output_dir or (configs[0].output_dir if configs else runs[0].path.parent))
    given = "+".join(r.path.name for r in runs)  # as --eval names its sets: another set of runs, another folder
    out = root / f"comparison_branches_{name}_plan{runs[0].plan}_{given}_{args.method}_{label}"
    listed = _claim_branch_folder(out, [r.path for r in runs])
    predictions = branch_predictions(checkpoints, args.branches, args.method, label)
    described = f"{args.method}'s chunks at plan {runs[0].plan} of {', '.join(args.branches)}"
    spread = outcome_spread(predictions)
    picked = selection(predictions, list(checkpoints), n_resamples=args.bootstrap, seed=args.bootstrap_seed)
    section = branch_markdown(spread, picked, runs[0].plan, label)
    if checkpoints:
        comparison = compare_predictions(predictions, list(checkpoints), n_resamples=args.bootstrap, seed=args.bootstrap_seed,
                                         n_bins=configs[0].train.ece_bins, label=label, baselines=False)
        if label == "horizon" and not runs[0].delivers:
            comparison.label_meaning = SCOOP_ONLY_HORIZON
        files = write_comparison(comparison, described, out)
        text = comparison_markdown(comparison, described) + "\n" + section
    else:  # the draws' spread alone: no model scores them
        files = [ensure_writable_dir(out) / "branch_spread.md", out / "branch_labels.csv"]
        text = f"# The draws of one state: {described}\n\n" + section
        write_text_atomic(files[1], predictions.to_csv(index=False))
    write_text_atomic(files[0], text)
    write_text_atomic(out / "branch_selection.csv", picked.to_csv(index=False))
    write_json_atomic(out / BRANCH_RUNS_FILE, {"runs": listed})
    print(text)
    print(f"written: {', '.join(str(f) for f in [*files, out / 'branch_selection.csv'])}")
    return 0


def _run(args: argparse.Namespace) -> int:
    import torch

    from grits_lab.config import load_config
    from grits_lab.errors import InputError
    from grits_lab.io import check_writable_dir
    from grits_lab.spillage.compare import compare_predictions, comparison_markdown, predict_all, write_comparison
    from grits_lab.spillage.predictor_config import PredictorConfig
    from grits_lab.spillage.predictor_training import run_dir

    if args.bootstrap < 100:
        raise InputError(f"--bootstrap must be at least 100 (got {args.bootstrap})")
    if not args.configs:
        if not args.branches:
            raise InputError("give at least one predictor CONFIG (only --branches runs without one: the draws' spread alone)")
        return _branches(args, {}, [], args.label or "horizon")
    checkpoints: dict[str, Path] = {}
    configs = [load_config(path, PredictorConfig) for path in args.configs]
    for path, config in zip(args.configs, configs):
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
    label = args.label or configs[0].data.label
    if args.branches:
        return _branches(args, checkpoints, configs, label)
    out = Path(configs[0].output_dir) / f"comparison_{'+'.join(Path(d).name for d in args.eval)}"
    if label != "chunk":  # scored against another label: its own table, beside the chunk label's
        out = out.with_name(f"{out.name}_{label}")
    check_writable_dir(out)  # before the predictions, not after them
    predictions = predict_all(checkpoints, args.eval, label=label)
    comparison = compare_predictions(predictions, list(checkpoints), n_resamples=args.bootstrap, seed=args.bootstrap_seed, n_bins=configs[0].train.ece_bins, label=label)
    files = write_comparison(comparison, ", ".join(args.eval), out)
    print(comparison_markdown(comparison, ", ".join(args.eval)))
    print(f"written: {', '.join(str(f) for f in files)}")
    return 0
