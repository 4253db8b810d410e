"""`python -m studies.outcome_sensitivity ...`: how much of an outcome is chance (README.md).

    nudge CONFIG --offset M [--draw N] --output-dir DIR    an evaluation with every scoop action nudged
    branch CONFIG --plan K --draw N --output-dir DIR       an evaluation whose plan K samples draw N
    compare BEFORE AFTER [--declared] [--output-dir DIR]   two runs paired, with each outcome's AUROC ceiling
    branches RUN... [--predictors CONFIG...]               predictors scored within each branched state

`nudge` and `branch` take every argument of `grits-lab evaluate` and run it with the study's scoop
hook (hooks.py `OutcomeHook`); the records name the hook's settings (`scoop_action_offset_m`, ...).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from grits_lab.cli import run_command
from grits_lab.cli.compare_commands import add_predictor_arguments, predictor_checkpoints
from grits_lab.cli.evaluate_commands import add_evaluation_arguments, run_evaluation
from grits_lab.errors import InputError


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m studies.outcome_sensitivity", description=__doc__.split("\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    nudge = commands.add_parser("nudge", help="evaluate with every executed scoop action nudged (the same seeds)")
    add_evaluation_arguments(nudge)
    nudge.add_argument("--offset", type=float, required=True, metavar="M", help="the nudge in metres, e.g. 0.0005")
    nudge.add_argument("--draw", type=int, default=0, metavar="N", help="which seeded set of directions (default 0)")
    nudge.set_defaults(handler=_nudge)
    branch = commands.add_parser("branch", help="evaluate with one plan drawing other initial noise (a diffusion policy's)")
    add_evaluation_arguments(branch)
    branch.add_argument("--plan", type=int, required=True, metavar="K", help="the plan that branches (0 = the scoop's first)")
    branch.add_argument("--draw", type=int, default=0, metavar="N", help="its noise draw (0: the unbranched episode)")
    branch.add_argument("--offset", type=float, default=0.0, metavar="M",
                        help="also nudge the actions from the branch plan on, in metres (a nudged replay of the same sample)")
    branch.add_argument("--offset-draw", type=int, default=0, metavar="N", help="the nudge's set of directions (default 0)")
    branch.set_defaults(handler=_branch)
    compare = commands.add_parser("compare", help="two runs on the same seeds paired, with each outcome's AUROC ceiling")
    compare.add_argument("before", metavar="BEFORE", help="run directory (the reference)")
    compare.add_argument("after", metavar="AFTER", help="run directory on the same seeds")
    compare.add_argument("--output-dir", metavar="DIR", help="also write comparison.csv and comparison.md there")
    compare.add_argument("--declared", action="store_true",
                         help="add the ceilings even where the records name no difference (e.g. CPU kernels, for records "
                              "made before `cpu_kernels` was recorded): the runs are two draws of one chance")
    compare.set_defaults(handler=_compare)
    scores = commands.add_parser("branches", help="score predictors on the chunks branched runs executed at their branch plan")
    scores.add_argument("runs", nargs="+", metavar="RUN", help="run directories of `branch` with one --plan and different --draw")
    scores.add_argument("--predictors", nargs="+", default=[], metavar="CONFIG",
                        help="predictor configs; the first is the reference (none: the draws' spread alone)")
    scores.add_argument("--method", default="dp", metavar="METHOD", help="whose rollout chunks to score (default dp)")
    add_predictor_arguments(scores)
    scores.set_defaults(handler=_branches)
    return parser


def _nudge(args: argparse.Namespace) -> int:
    from studies.outcome_sensitivity.hooks import OutcomeHook

    return run_evaluation(args, OutcomeHook(offset=args.offset, offset_draw=args.draw))


def _branch(args: argparse.Namespace) -> int:
    from studies.outcome_sensitivity.hooks import OutcomeHook

    return run_evaluation(args, OutcomeHook(offset=args.offset, offset_draw=args.offset_draw, branch_plan=args.plan,
                                            branch_draw=args.draw))


def _compare(args: argparse.Namespace) -> int:
    from grits_lab.report.run_compare import compare_run_dirs, write_comparison
    from studies.outcome_sensitivity.ceiling import ceiling_columns

    table, markdown = compare_run_dirs(args.before, args.after, per_method=ceiling_columns(args.declared))
    print(markdown)
    if args.output_dir:
        print(f"written: {', '.join(str(f) for f in write_comparison(table, markdown, args.output_dir))}")
    return 0


BRANCH_RUNS_FILE = "branch_runs.json"  # the run directories a `branches` comparison folder was written from


def _claim_branch_folder(out: Path, runs: list[Path]) -> list[str]:
    """The resolved run directories of a `branches` comparison; InputError when `out` already holds
    the comparison of other runs of the same names (two studies' `draw0`, `draw1`): it is kept."""
    import json

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


def _branches(args: argparse.Namespace) -> int:
    """`branches RUN... [--predictors CONFIG...]`: the comparison within states, the draws' spread and each predictor's pick."""
    from grits_lab.io import ensure_writable_dir, write_json_atomic, write_text_atomic
    from grits_lab.spillage.compare import compare_predictions, comparison_markdown, write_comparison
    from studies.outcome_sensitivity.branches import (SCOOP_ONLY_HORIZON, branch_markdown, branch_predictions, branch_runs,
                                                      check_model_names, outcome_spread, selection)

    if args.predictors:
        checkpoints, configs, label = predictor_checkpoints(args, args.predictors)
    else:
        if args.bootstrap < 100:
            raise InputError(f"--bootstrap must be at least 100 (got {args.bootstrap})")
        checkpoints, configs, label = {}, [], args.label or "horizon"

    runs = branch_runs(args.runs, args.method)  # before any model runs
    check_model_names(list(checkpoints))
    predictions = branch_predictions(checkpoints, args.runs, args.method, label)
    from grits_lab.config import parse_yaml

    config_file = runs[0].path / "config.yaml"
    name = (parse_yaml(config_file.read_text(), config_file) or {}).get("run_id", runs[0].path.name)
    root = Path(args.output_dir or (configs[0].output_dir if configs else runs[0].path.parent))
    given = "+".join(r.path.name for r in runs)  # as --held-out names its sets: another set of runs, another folder
    out = root / f"comparison_branches_{name}_plan{runs[0].plan}_{given}_{args.method}_{label}"
    listed = _claim_branch_folder(out, [r.path for r in runs])
    described = f"{args.method}'s chunks at plan {runs[0].plan} of {', '.join(args.runs)}"
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



def main(argv: list[str] | None = None) -> int:
    return run_command(build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
