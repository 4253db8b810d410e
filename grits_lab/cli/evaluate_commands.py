"""`grits-lab evaluate CONFIG` (every configured method on foods x levels x trials, records to Parquet, resumable)
and `grits-lab replay RUN_DIR` (one recorded episode again, checked against its record, with a video)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from grits_lab.cli.flags import NO_PROGRESS_HELP, retire


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="evaluate methods on the whole task (scoop -> transfer -> pour); resumable",
        description=(
            "Run every method of an evaluation config on its foods x levels x trials (the same seeds "
            "for every method) over Ray or serially, writing one record per episode to "
            "OUTPUT_DIR/episodes.parquet with config.yaml and provenance.json beside it. Running the "
            "same command again skips finished episodes. Exit status 1 when any recorded episode "
            "failed (its error is kept in the records), 2 for bad input."
        ),
    )
    add_evaluation_arguments(parser)
    retire(parser, "--fresh", "--restart")
    retire(parser, "--branch-draw", "`python -m studies.outcome_sensitivity branch CONFIG --plan K --draw N`")
    retire(parser, "--action-offset-draw", "`python -m studies.outcome_sensitivity nudge CONFIG --offset M --draw N`")
    parser.set_defaults(handler=_run)

    replay = subparsers.add_parser(
        "replay",
        help="re-run one recorded evaluation episode, check it reproduces its record, optionally film it",
        description=(
            "Re-run the episode (method, food, level, trial) of an evaluation run directory from its record: "
            "the same seed, the run's config.yaml, the recorded guidance (rho, s) and the checkpoints, "
            "checked by digest. Compares every recorded metric with the replay (exit code 0: equal, 1: "
            "diverged; a divergence on other CPU kernels than the record's says so) and, with --video, writes a captioned video from a camera that shows the spoon and both bowls."
        ),
    )
    replay.add_argument("run_dir", help="run directory of `grits-lab evaluate` (episodes.parquet, config.yaml)")
    replay.add_argument("--method", required=True, help="method name as recorded, e.g. dp or grits")
    replay.add_argument("--food", required=True)
    replay.add_argument("--level", required=True, help="quantity level, e.g. low")
    replay.add_argument("--trial", type=int, required=True, help="trial index within (food, level), 0-based")
    replay.add_argument("--video", default=None, help="write a captioned video: FILE.mp4 (H.264) or FILE.gif")
    replay.add_argument("--every", type=int, default=1, help="render every k-th action (default 1: every 0.1 s)")
    replay.add_argument("--plan-figure", default=None, metavar="FILE.png",
                        help="draw one guided plan: the unguided and guided executed chunks (same noise) over the composite cloud, with P(spill) of each")
    replay.add_argument("--plan", type=int, default=None, help="which plan to draw (default: the one guidance moved farthest)")
    replay.add_argument("--json", action="store_true", help="print exactly one JSON object")
    replay.set_defaults(handler=_replay)


def add_evaluation_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of `grits-lab evaluate` (the config, --override, --methods, --checkpoint, --output-dir,
    --address, --serial, --restart, --no-progress), for a command that runs an evaluation with a
    scoop hook (a study's `__main__`); `run_evaluation` reads them."""
    parser.add_argument("config", help="evaluation config, e.g. experiments/evaluate_quick.yaml")
    parser.add_argument("--override", metavar="YAML", action="append", default=None,
                        help="YAML merged over the config (any of its keys), e.g. a sweep's best.yaml with `guidance: {rho: ..., s: ...}`; "
                             "repeat it to merge several, in order, mappings key by key")
    parser.add_argument("--methods", nargs="+", default=None, help="evaluate only these methods (default: the config's)")
    parser.add_argument("--checkpoint", metavar="KEY=PATH", action="append", default=None,
                        help="a trained model the methods load, e.g. policy=results/policy_cpu/checkpoints/last.pt "
                             "(overrides checkpoints.KEY; keys: policy, predictor, predictor_raw, predictor_pointnet2, "
                             "predictor_horizon, bc, demos); repeat it for several")
    parser.add_argument("--output-dir", metavar="DIR", default=None, help="run directory (overrides the config's output_dir)")
    parser.add_argument("--address", help="Ray cluster address (overrides executor.address and RAY_ADDRESS)")
    parser.add_argument("--serial", action="store_true", help="run in this process instead of on Ray")
    parser.add_argument("--restart", action="store_true", help="discard the run directory's records and start over")
    parser.add_argument("--no-progress", action="store_true", help=NO_PROGRESS_HELP)


def _run(args: argparse.Namespace) -> int:
    return run_evaluation(args)


def run_evaluation(args: argparse.Namespace, hook: Any = None) -> int:
    """`grits-lab evaluate` with the arguments of `add_evaluation_arguments`, every episode's scoop
    hooked by `hook` (a `ScoopHook`; None: none). Returns the exit status."""
    from grits_lab.config import load_yaml, merge_mappings
    from grits_lab.errors import ConfigError, InputError
    from grits_lab.evaluation.evaluation_config import load_evaluation_config
    from grits_lab.evaluation.evaluation_run import evaluate, failed_episodes_line, summary_table

    overrides: dict = {}
    for path in args.override or []:
        layer = dict(load_yaml(path))
        if "guidance" in layer and not isinstance(layer["guidance"], dict):
            raise ConfigError(f"{path}: `guidance` must be a mapping like {{rho: 2.5, s: 30}}")
        overrides = merge_mappings(overrides, layer)
    # Every key of the file is merged over the config (and validated with it: an unknown key is
    # one error naming it); the command-line flags below win over the file.
    if args.methods:
        overrides["methods"] = list(args.methods)
    for given in args.checkpoint or []:
        key, sep, path = given.partition("=")
        if not sep or not key or not path:
            raise InputError(f"--checkpoint takes KEY=PATH, e.g. policy=results/policy_cpu/checkpoints/last.pt; got {given!r}")
        overrides["checkpoints"] = {**overrides.get("checkpoints", {}), key: path}  # an unknown key fails at load, named
    if args.output_dir:
        overrides["output_dir"] = args.output_dir
    if args.address:
        overrides["executor"] = {**overrides.get("executor", {}), "address": args.address}
    if args.serial:
        overrides["executor"] = {**overrides.get("executor", {}), "backend": "serial"}
    try:
        config = load_evaluation_config(args.config, overrides)
    except ConfigError as error:
        if not args.override:
            raise
        raise ConfigError(f"{error} (the config merged with --override {', '.join(args.override)})") from error
    records = evaluate(config, progress=not args.no_progress, restart=args.restart, hook=hook)
    print(summary_table(records))
    print(f"records: {config.output_dir}/episodes.parquet ({len(records)} episodes); tables and figures: {report_hint(config.output_dir)}")
    # Episodes that raised are recorded (and skipped on resume) like any other; the exit status says so.
    failed = failed_episodes_line(records, f"{config.output_dir}/episodes.parquet")
    if failed:
        print(f"grits-lab: error: {failed}", file=sys.stderr)
        return 1
    return 0


def _replay(args: argparse.Namespace) -> int:
    import json

    from grits_lab.errors import InputError
    from grits_lab.report.replay import replay_episode
    from grits_lab.sim.video import check_video_path

    if args.video is not None:
        check_video_path(args.video)  # before the simulator starts
    if args.every < 1:
        raise InputError(f"--every must be at least 1. Got {args.every}.")
    if args.plan_figure is not None and not args.plan_figure.endswith(".png"):
        raise InputError(f"--plan-figure must name a .png file. Got {args.plan_figure!r}.")
    result = replay_episode(args.run_dir, method=args.method, food=args.food, level=args.level, trial=args.trial,
                            video=args.video, every=args.every, plan_figure=args.plan_figure, plan=args.plan,
                            progress=args.video is not None and not args.json)
    if args.json:
        print(json.dumps(result.to_dict()))
    else:
        print(result.describe())
        if result.video:
            print(f"video: {result.video} ({result.frames} frames)")
        if result.plan_figure:
            print(f"guidance picture: {result.plan_figure}")
    return 0 if result.matches else 1


def report_hint(output_dir: str) -> str:
    """The `grits-lab report` command for a run directory, quoted for a POSIX shell (spaces, `$`, quotes)."""
    import shlex

    return f"grits-lab report {shlex.quote(str(output_dir))}"
