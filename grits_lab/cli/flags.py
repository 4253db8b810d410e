"""One flag per meaning in every command, and the old spellings that still work.

- `--level`: a food's quantity level (low / medium / high).
- `--output-dir`: where the command writes; for a config-driven command it overrides the
  config's `output_dir` key.
- `--restart`: discard what an earlier run of the same command left (records, checkpoints) and
  start over. `grits-lab pipeline --force STAGE` means something else: run the stage even though
  it is up to date, and the stage resumes its outputs like any rerun (nothing is discarded).

An old spelling is a hidden option with the `DeprecatedFlag` action: it stores what the new flag
would and prints one line to stderr, e.g. `grits-lab: --quantity is deprecated; use --level`.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from grits_lab.errors import warn_deprecated


class DeprecatedFlag(argparse.Action):
    """An old spelling of a flag: stores its value (or `const`, with nargs=0) and warns once (a
    command line builds its own parser).

    `use` names what to write instead (the new flag, perhaps with a word on what changed).
    """

    def __init__(self, option_strings: Sequence[str], dest: str, use: str, **kwargs: Any) -> None:
        kwargs.setdefault("help", argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kwargs)
        self.use = use
        self.warned = False

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        if not self.warned:
            self.warned = True
            warn_deprecated(option_string or self.option_strings[0], self.use)
        setattr(namespace, self.dest, self.const if self.nargs == 0 else values)


def add_flag(parser: Any, name: str, *, deprecated: Sequence[str] = (), required: bool = False,
             **kwargs: Any) -> argparse.Action:
    """`parser.add_argument(name, **kwargs)` plus each spelling in `deprecated` as a hidden alias.

    A required flag and its aliases form a required group: either spelling satisfies it.
    """
    target = parser.add_mutually_exclusive_group(required=True) if required and deprecated else parser
    action = target.add_argument(name, required=required and not deprecated, **kwargs)
    for old in deprecated:
        target.add_argument(old, dest=action.dest, action=DeprecatedFlag, use=name, nargs=action.nargs,
                            const=action.const, type=action.type, choices=action.choices,
                            metavar=action.metavar, default=argparse.SUPPRESS)
    return action

