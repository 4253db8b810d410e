"""`python -m studies.scoop_convergence ...`: does the scoop's physics converge? (README.md)

    run CONFIG --output-dir DIR [--checkpoint KEY=PATH] [--methods M...] [--settings NAME...] [--serial]
        every setting's scoops, plain and nudged (one resumable evaluation run each, under DIR)
    summarize DIR --summary-to FOLDER
        per setting: the rates with Wilson intervals, the counts, the cost, and the choice rule's verdict
    power [--summary-to FOLDER]
        chains and paired seeds that decide the paper's 0.6x, from the committed summaries (power.py)
"""

from __future__ import annotations

import argparse
import sys

from grits_lab.cli import run_command
from grits_lab.errors import InputError


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m studies.scoop_convergence", description=__doc__.split("\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser("run", help="play every setting's scoops, plain and nudged (resumable)")
    run.add_argument("config", metavar="CONFIG", help="study config, e.g. studies/scoop_convergence/configs/scoop_convergence.yaml")
    run.add_argument("--output-dir", required=True, metavar="DIR", help="where the runs go: DIR/<setting>/<variant>")
    run.add_argument("--checkpoint", metavar="KEY=PATH", action="append", default=None,
                     help="a model the methods load; policy=PATH adds DP beside the expert")
    run.add_argument("--methods", nargs="+", default=None, help="only these methods (default: expert, and dp with a policy)")
    run.add_argument("--settings", nargs="+", default=None, metavar="NAME", help="only these settings of the config")
    run.add_argument("--serial", action="store_true", help="run in this process instead of on Ray")
    run.add_argument("--no-progress", action="store_true", help="no progress bars")
    run.set_defaults(handler=_run)
    summarize = commands.add_parser("summarize", help="the convergence table and the choice rule's verdict")
    summarize.add_argument("output_dir", metavar="DIR", help="the --output-dir of `run`")
    summarize.add_argument("--summary-to", required=True, metavar="FOLDER",
                           help="folder for convergence.csv and README.md, e.g. studies/scoop_convergence/summaries/NAME")
    summarize.set_defaults(handler=_summarize)
    power = commands.add_parser("power", help="chains and seeds that decide the paper's 0.6x (from committed summaries)")
    power.add_argument("--summary-to", default=None, metavar="FOLDER", help="also write power.csv and README.md there")
    power.set_defaults(handler=_power)
    return parser


def _run(args: argparse.Namespace) -> int:
    from studies.scoop_convergence.convergence import load_convergence_config, run_study

    config = load_convergence_config(args.config)
    overrides: dict = {}
    for given in args.checkpoint or []:
        key, sep, path = given.partition("=")
        if not sep or not key or not path:
            raise InputError(f"--checkpoint takes KEY=PATH, e.g. policy=results/policy_cpu/checkpoints/last.pt; got {given!r}")
        overrides.setdefault("checkpoints", {})[key] = path
    if args.methods:
        overrides["methods"] = list(args.methods)
    elif "policy" in overrides.get("checkpoints", {}):
        overrides["methods"] = ["expert", "dp"]
    if args.serial:
        overrides["executor"] = {"backend": "serial"}
    return run_study(config, args.output_dir, overrides, progress=not args.no_progress, only=args.settings)


def _summarize(args: argparse.Namespace) -> int:
    from studies.scoop_convergence.convergence import write_summary

    files = write_summary(args.output_dir, args.summary_to)
    print(files[1].read_text())
    print(f"written: {', '.join(str(f) for f in files)}")
    return 0


def _power(args: argparse.Namespace) -> int:
    from studies.scoop_convergence.power import power_report

    print(power_report(args.summary_to))
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_command(build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
