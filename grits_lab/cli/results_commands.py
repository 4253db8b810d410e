"""`grits-lab results render | check`: the results pages rendered from the committed experiment summaries."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "results",
        help="render README.md, docs/results.md and the studies' and archive's pages from the committed summaries",
        description=(
            "Rewrite the generated blocks (between `<!-- generated: KIND NAME -->` and `<!-- end generated -->`) of "
            "README.md, docs/results.md and the studies' pages from studies/*/summaries/*/summary.csv (and docs/archive/*/) and its "
            "companions, written by `grits-lab report RUN_DIR --summary-to studies/STUDY/summaries/NAME`. Text outside the "
            "blocks is kept."
        ),
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, text in (("render", "rewrite the pages whose generated blocks differ from the summaries"),
                       ("check", "list the pages that differ from the summaries; exit 1 if any does")):
        action = actions.add_parser(name, help=text, description=text)
        action.add_argument("--root", metavar="DIR", default=".", help="the checkout holding README.md and docs/ (default: .)")
        action.set_defaults(handler=_render if name == "render" else _check)


def _render(args: argparse.Namespace) -> int:
    from grits_lab.report.results_pages import write_all

    changed = write_all(args.root)
    print("\n".join(f"rendered {page}" for page in changed) if changed else "every page matches its summaries")
    return 0


def _check(args: argparse.Namespace) -> int:
    from grits_lab.report.results_pages import drifted

    stale = drifted(args.root)
    for page in stale:
        print(f"{page} differs from its summaries: run `grits-lab results render`")
    if not stale:
        print("every page matches its summaries")
    return 1 if stale else 0
