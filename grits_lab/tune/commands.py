"""`grits-lab sweep`: run (or resume, or join) an Optuna study over GRITS's rho and s, then write its outputs."""

from __future__ import annotations

import argparse
import sys


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
    parser.add_argument("--report-only", action="store_true",
                        help="run no trial; rewrite the tables, best.yaml and plots from the storage")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (one line per trial)")
    parser.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    import dataclasses

    import optuna

    from grits_lab.errors import InputError, StorageError
    from grits_lab.io import ensure_writable_dir
    from grits_lab.tune.config import load_study_config
    from grits_lab.tune.objective import make_evaluator
    from grits_lab.tune.outputs import write_outputs
    from grits_lab.tune.storage import open_storage
    from grits_lab.tune.study import EVALUATOR_ATTR, open_study, run_trials

    config = load_study_config(args.config)
    if args.n_trials is not None:
        if args.n_trials < 1:
            raise InputError(f"--n-trials must be >= 1. Got {args.n_trials}.")
        config = dataclasses.replace(config, n_trials=args.n_trials)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    # The evaluator is built before the storage is touched: a missing evaluation layer or
    # checkpoint fails at once, without leaving an empty study behind.
    evaluator = None if args.report_only else make_evaluator(config)
    storage, where = open_storage(args.storage or config.storage, config.out_dir / "journal.log")
    out_dir = ensure_writable_dir(config.out_dir)
    if args.report_only:
        try:
            study = optuna.load_study(study_name=config.study_name, storage=storage)
        except KeyError:
            raise StorageError(f"no study named `{config.study_name}` in {where}") from None
        from grits_lab.tune.grits_binding import GritsEvaluator
        from grits_lab.tune.synthetic import SyntheticEvaluator

        kind = study.user_attrs.get(EVALUATOR_ATTR, config.evaluator)
        label = SyntheticEvaluator.label if kind == "synthetic" else GritsEvaluator.label
    else:
        assert evaluator is not None
        study = open_study(config, storage)
        label = evaluator.label
        print(f"sweep {config.study_name}: {label}; storage {where}; "
              f"{len(config.validation.episodes())} episodes per trial; study budget {config.n_trials} trials",
              file=sys.stderr)
        try:
            run_trials(config, study, storage, evaluator, records_dir=out_dir / "records",
                       progress=not args.no_progress,
                       after_trial=lambda st: write_outputs(st, config, out_dir, where, label, plots=False))
        finally:
            evaluator.close()
    summary = write_outputs(study, config, out_dir, where, label, plots=not args.no_plots)
    _print_summary(summary, out_dir)
    return 0


def _print_summary(summary: dict, out_dir) -> None:
    def describe(m: dict | None) -> str:
        if m is None:
            return "not evaluated yet"
        return (f"trial {m['trial']}: rho={m['rho']:.3g} s={m['s']} success={m['success_rate']:.3f} "
                f"spillage={m['spillage_rate']:.3f} scoop_failure={m['scoop_failure_rate']:.3f} "
                f"({m['n_episodes']} episodes)")

    print(f"trials: {summary['states']}")
    print(f"best      {describe(summary['best'])}  [{summary['best_rule']}]")
    print(f"defaults  {describe(summary['defaults'])}")
    for note in summary["notes"]:
        print(note)
    print(f"outputs in {out_dir}: trials.csv, trials.parquet, best.yaml, summary.json, pareto.png, importance.png")
    print(f"dashboard: {summary['dashboard']}   (pip install -e '.[dashboard]')")
