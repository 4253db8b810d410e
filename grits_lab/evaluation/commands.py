"""`grits-lab evaluate CONFIG`: every configured method on foods x levels x trials, records to Parquet, resumable."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="evaluate methods on the whole task (scoop -> transfer -> pour); resumable",
        description=(
            "Run every method of an evaluation config on its foods x levels x trials (the same seeds "
            "for every method) over Ray or serially, writing one record per episode to "
            "OUTPUT_DIR/episodes.parquet with config.yaml and provenance.json beside it. Running the "
            "same command again skips finished episodes."
        ),
    )
    parser.add_argument("config", help="evaluation config, e.g. experiments/evaluate_quick.yaml")
    parser.add_argument("--override", metavar="YAML", default=None,
                        help="YAML merged over the config (any of its keys), e.g. a sweep's best.yaml with `guidance: {rho: ..., s: ...}`")
    parser.add_argument("--methods", nargs="+", default=None, help="evaluate only these methods (default: the config's)")
    parser.add_argument("--output-dir", default=None, help="run directory (default: the config's output_dir)")
    parser.add_argument("--serial", action="store_true", help="run in this process instead of on Ray")
    parser.add_argument("--fresh", action="store_true", help="discard the run directory's records and start over")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from grits_lab.config import load_yaml
    from grits_lab.evaluation.config import load_evaluation_config
    from grits_lab.evaluation.run import evaluate, summary_table

    overrides = dict(load_yaml(args.override)) if args.override else {}
    if "guidance" in overrides and not isinstance(overrides["guidance"], dict):
        from grits_lab.errors import ConfigError

        raise ConfigError(f"{args.override}: `guidance` must be a mapping like {{rho: 2.5, s: 30}}")
    # Every key of the file is merged over the config (and validated with it: an unknown key is
    # one error naming it); the command-line flags below win over the file.
    if args.methods:
        overrides["methods"] = list(args.methods)
    if args.output_dir:
        overrides["output_dir"] = args.output_dir
    if args.serial:
        overrides["executor"] = {"backend": "serial"}
    config = load_evaluation_config(args.config, overrides)
    records = evaluate(config, progress=not args.no_progress, fresh=args.fresh)
    print(summary_table(records))
    print(f"records: {config.output_dir}/episodes.parquet ({len(records)} episodes); tables and figures: grits-lab report {config.output_dir}")
    return 0
