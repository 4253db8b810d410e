"""One flag per meaning in every command, and the retired spellings that name their successor.

- `--level`: a food's quantity level (low / medium / high).
- `--output-dir`: where the command writes; for a config-driven command it overrides the
  config's `output_dir` key. Every command that writes has it.
- `--address`: the Ray cluster to run on (overrides the config's `executor.address` and
  RAY_ADDRESS). Every command that runs on Ray has it.
- `--restart`: discard what an earlier run of the same command left (records, checkpoints) and
  start over. `grits-lab pipeline --rerun STAGE` means something else: run the stage even though
  it is up to date, and the stage resumes its outputs like any rerun (nothing is discarded).
- `--no-progress`: no progress bars or per-epoch lines (logs, CI).
- `--video FILE`: write a video file (replay, rollout); `report --video-episodes N` films N episodes.
- `--held-out DATASET`: the held-out spillage dataset a predictor is scored on (train predictor,
  compare-predictors); `--dataset` is always training data.
- `--checkpoint KEY=PATH` (evaluate): a trained model a method loads, instead of a placeholder
  override file; `--checkpoint best|last` (train predictor, compare-predictors) picks a run's own.
- Seeds, one name per meaning: `--root-seed` (collect: the seed every episode's seed is derived
  from), `--episode-seed` (rollout, scene: one episode's world), `--bowl-seed` (foods: the
  settled bowl whose fill height is measured), `--bootstrap-seed` (compare-predictors).

A retired spelling (docs/migration.md) is a hidden option with the `RetiredFlag` action: giving
it stops the command with one line naming the flag to use, e.g.
`grits-lab: error: --quantity is retired; use --level (docs/migration.md)`.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from grits_lab.errors import InputError


NO_PROGRESS_HELP = "no progress bars or per-epoch lines (logs, CI)"


class RetiredFlag(argparse.Action):
    """A retired spelling of a flag: InputError naming `use`, what to write instead."""

    def __init__(self, option_strings: Sequence[str], dest: str, use: str, **kwargs: Any) -> None:
        kwargs.setdefault("help", argparse.SUPPRESS)
        kwargs.setdefault("nargs", "?")
        super().__init__(option_strings, dest, **kwargs)
        self.use = use

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        raise InputError(f"{option_string or self.option_strings[0]} is retired; use {self.use} (docs/migration.md)")


def retire(parser: Any, old: str, use: str) -> None:
    """Add `old` to `parser` as a retired spelling whose use is one line naming `use`."""
    parser.add_argument(old, action=RetiredFlag, use=use, dest=f"retired_{old.lstrip('-').replace('-', '_')}",
                        default=argparse.SUPPRESS)
