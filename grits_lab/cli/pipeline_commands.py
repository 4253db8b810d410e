"""`grits-lab pipeline CONFIG`: every stage from data collection to the report, resumable."""

from __future__ import annotations

import argparse

from grits_lab.cli.flags import NO_PROGRESS_HELP, retire


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "pipeline",
        help="collect -> train -> evaluate -> sweep -> report in one command (resumable stage by stage)",
        description=(
            "Run every stage a pipeline config lists, in order. A stage whose outputs exist and whose "
            "config (and upstream stages) are unchanged is skipped; an interrupted stage resumes."
        ),
    )
    parser.add_argument("config", help="pipeline config, e.g. experiments/quickstart.yaml")
    parser.add_argument("--only", nargs="+", metavar="STAGE", help="run only these stages")
    parser.add_argument("--rerun", nargs="+", metavar="STAGE", default=[], help="run these stages even if up to date; each resumes its outputs (nothing is discarded)")
    parser.add_argument("--address", help="Ray cluster address for collection and evaluation (overrides `address` in the config and RAY_ADDRESS)")
    parser.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    retire(parser, "--force", "--rerun")
    parser.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from grits_lab.errors import InputError
    from grits_lab.pipeline.pipeline_config import load_pipeline_config
    from grits_lab.pipeline.pipeline_run import run_pipeline

    config = load_pipeline_config(args.config)
    if args.address:
        config.address = args.address
    for name in (args.only or []) + list(args.rerun):
        if name not in config.stages:
            raise InputError(f"unknown stage `{name}`; this pipeline has: {', '.join(config.ordered_stages())}")
    results = run_pipeline(config, only=args.only, force=args.rerun, progress=not args.no_progress)
    print(f"\npipeline {config.name}: outputs in {config.output_dir}")
    for stage, result in results.items():
        seconds = result.get("seconds")
        timing = f"{seconds:>7.0f} s" if isinstance(seconds, (int, float)) else " " * 9
        print(f"  {stage:<20} {result['status']:<13} {timing}")
    from pathlib import Path

    from grits_lab.pipeline.closing import closing_lines
    from grits_lab.pipeline.stages import Layout

    for line in closing_lines(Layout(Path(config.output_dir)), config.ordered_stages()):
        print(line)
    if "report" in results:
        print(f"report: {config.output_dir}/report/report.html")
    return 0
