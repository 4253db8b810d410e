"""`grits-lab sweep`: run (or resume, or join) an Optuna study over GRITS's rho and s, then write its outputs."""

from __future__ import annotations

import argparse

from grits_lab.cli.flags import NO_PROGRESS_HELP


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "sweep",
        help="tune GRITS's guidance weight rho and threshold s with Optuna (resumable, multi-worker)",
        description=(
            "Run an Optuna study over rho and s as configured by a sweep file (sweeps/*.yaml). "
            "Running the same command again resumes the study; running it on several machines "
            "with one storage URL shares the work."
        ),
    )
    parser.add_argument("config", help="sweep file, e.g. sweeps/grits_quick.yaml")
    parser.add_argument("--n-trials", type=int, default=None,
                        help="total trials the study should hold (overrides n_trials in the file)")
    parser.add_argument("--storage", default=None,
                        help="storage URL or journal file path (overrides `storage` in the file)")
    parser.add_argument("--address", help="Ray cluster the trials' episodes run on (sets RAY_ADDRESS; an executor.address "
                                          "in the evaluation config wins)")
    parser.add_argument("--report-only", action="store_true",
                        help="run no trial; rewrite the tables, best.yaml, the front/ overrides and plots from the storage")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)
    parser.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from grits_lab.errors import InputError
    from grits_lab.tune.study_config import load_study_config
    from grits_lab.tune.job import run_sweep

    if args.n_trials is not None and args.n_trials < 1:
        raise InputError(f"--n-trials must be >= 1. Got {args.n_trials}.")
    config = load_study_config(args.config)
    if args.address:
        import os

        os.environ["RAY_ADDRESS"] = args.address  # the evaluation config's executor reads it (grits_lab/runners)
    summary = run_sweep(config, n_trials=args.n_trials, storage=args.storage, report_only=args.report_only,
                        plots=not args.no_plots, progress=not args.no_progress)
    _print_summary(summary, config.study_dir)
    return 0


def _print_summary(summary: dict, out_dir) -> None:
    from grits_lab.tune.reference import paired_line

    def describe(m: dict | None) -> str:
        if m is None:
            return "not evaluated yet"
        return (f"trial {m['trial']}: rho={m['rho']:.3g} s={m['s']} success={m['success_rate']:.3f} "
                f"spillage={m['spillage_rate']:.3f} scoop_failure={m['scoop_failure_rate']:.3f} "
                f"({m['n_episodes']} episodes)")

    print(f"trials: {summary['states']}")
    print(f"best      {describe(summary['best'])}  [{summary['best_rule']}]")
    print(f"defaults  {describe(summary['defaults'])}")
    for method, ref in summary.get("reference", {}).items():
        print(f"reference {method}: success={ref['success_rate']:.3f} spillage={ref['spillage_rate']:.3f} "
              f"scoop_failure={ref['scoop_failure_rate']:.3f} ({ref['n_episodes']} episodes)")
        if ref["best"] is not None:
            print(f"  best {paired_line(ref['best'], method)}")
    for note in summary["notes"]:
        print(note)
    print(f"outputs in {out_dir}: {', '.join(summary['files'])}")
    print(f"dashboard: {summary['dashboard']}   (pip install -e '.[dashboard]')")
