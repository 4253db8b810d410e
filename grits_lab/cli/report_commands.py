"""`grits-lab report RUN_DIR [OTHER_RUN ...] [--output-dir DIR] [--methods METHOD ...] [--summary-to DIR] [--video-episodes N]`: the paper's tables and figures from a run's records, optionally with replayed episodes."""

from __future__ import annotations

import argparse

from grits_lab.cli.flags import retire


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
    parser.add_argument("also", metavar="OTHER_RUN", nargs="*",
                        help="more evaluation run directories whose records are reported beside RUN_DIR's, e.g. GRITS at a "
                             "sweep's tuned (rho, s) beside the paper's; a method run at several (rho, s) gets one row per setting")
    parser.add_argument("--output-dir", metavar="DIR", default=None, help="output directory (default: RUN_DIR/report)")
    retire(parser, "--out", "--output-dir")
    parser.add_argument("--real", metavar="FILE.csv", action="append", default=[],
                        help="real-robot trials (method, food, level, trial, task_success, spillage, scoop_failure; "
                             "grits_lab/report/real_trials.py) shown beside the simulation and the paper; repeatable")
    parser.add_argument("--methods", metavar="METHOD", nargs="+", default=[],
                        help="report only these methods' episodes (e.g. `--methods dp grits` when a run directory also holds "
                             "a method stopped early); a method the records do not hold is an error")
    parser.add_argument("--summary-to", metavar="DIR", default=None,
                        help="also write the experiment's committed summary into DIR (summary.csv, stage_cause.csv, claims.csv, "
                             "provenance.json, config.yaml; grits_lab/report/summary.py), e.g. studies/STUDY/summaries/NAME; "
                             "then `grits-lab results render`")
    parser.add_argument("--video-episodes", metavar="N", type=int, default=0,
                        help="replay up to N episodes per food under Diffusion Policy and GRITS (same seed) and show the videos "
                             "side by side (needs the run's checkpoints; RUN_DIR must be a `grits-lab evaluate` run directory)")
    retire(parser, "--videos", "--video-episodes")
    parser.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from grits_lab.errors import InputError
    from grits_lab.report.build import build_report

    replay = None
    if args.video_episodes < 0:
        raise InputError(f"--video-episodes must be 0 or more. Got {args.video_episodes}.")
    if args.video_episodes and args.also:
        raise InputError("--video-episodes replays episodes of one run directory; give RUN_DIR alone")
    if args.video_episodes:
        from grits_lab.report.replay import replay_episode

        run_dir = Path(args.run_dir)
        missing = [name for name in ("episodes.parquet", "config.yaml") if not (run_dir / name).is_file()]
        if missing:
            raise InputError(f"--video-episodes replays episodes from a `grits-lab evaluate` run directory; {run_dir} lacks {', '.join(missing)}")
        replay = replay_episode
    if args.summary_to:
        from grits_lab.io import check_writable_dir

        check_writable_dir(args.summary_to)  # before the report, not after it
    result = build_report(args.run_dir, args.output_dir, also=args.also, videos=args.video_episodes, replay=replay, progress=True,
                          real=args.real, methods=args.methods)
    print(f"report written to {result.out_dir} ({len(result.files)} files): {result.out_dir / 'report.html'}")
    for note in result.missing:
        print(f"  {note}")
    if args.summary_to:
        from grits_lab.report.run_records import load_run
        from grits_lab.report.summary import write_summary

        command = " ".join(["grits-lab report", args.run_dir, *args.also, *(["--methods", *args.methods] if args.methods else []),
                            "--summary-to", args.summary_to])
        files = write_summary(load_run(args.run_dir, exclude=result.out_dir, also=args.also, methods=args.methods),
                              args.summary_to, command)
        print(f"summary written to {args.summary_to} ({', '.join(f.name for f in files)}); render the pages: grits-lab results render")
    return 0
