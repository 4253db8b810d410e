"""`grits-lab report RUN_DIR [--out DIR]`: the paper's tables and figures from a run's records."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "report",
        help="tables and figures (Fig. 5, 6, 8, per-food breakdown, sweep summary) from evaluation records",
        description=(
            "Read per-episode evaluation records (episodes.parquet or *.parquet in RUN_DIR) and sweep "
            "outputs (trials.parquet/trials.csv), and write Markdown, CSV, LaTeX, PNG and one "
            "self-contained HTML report."
        ),
    )
    parser.add_argument("run_dir", metavar="RUN_DIR", help="evaluation or sweep run directory (or one .parquet file of records)")
    parser.add_argument("--out", metavar="DIR", default=None, help="output directory (default: RUN_DIR/report)")
    parser.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from grits_lab.report.build import build_report

    result = build_report(args.run_dir, args.out)
    print(f"report written to {result.out_dir} ({len(result.files)} files): {result.out_dir / 'report.html'}")
    for note in result.missing:
        print(f"  {note}")
    return 0
