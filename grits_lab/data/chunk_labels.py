"""Spill labels of a spillage episode's chunks.

Two labels per chunk (docs/datasets.md, "Two labels"):
- chunk (the paper's): did the spilled count rise while the chunk's own `n_action_steps` actions
  ran (from the spilled count after every step);
- horizon: is food spilled once the load is delivered that left at or after the chunk's first
  action (the rest of the scoop, the lift, the carry and the pour; from the step at which each
  finally spilled particle left), so a dig that heaps the spoon is blamed for the heap it sheds later.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

Label = Literal["chunk", "horizon"]
LABELS: tuple[str, ...] = ("chunk", "horizon")
# Per-chunk array and per-episode meta key of each label.
LABEL_ARRAYS = {"chunk": "chunk_spilled", "horizon": "chunk_spilled_horizon"}
TRIAL_LABELS = {"chunk": "label", "horizon": "label_horizon"}


def chunk_labels(spilled_over_time: np.ndarray, n_action_steps: int, spilled_before: int = 0,
                 n_steps: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(chunk_start (C,), chunk_spilled (C,)) from the spilled count after each step (S,).

    The first `n_steps` steps (default all) are cut into chunks of `n_action_steps`; a chunk
    spilled if the count at its end exceeds the count just before its first step.
    """
    counts = np.asarray(spilled_over_time, dtype=np.int64)
    n = len(counts) if n_steps is None else int(n_steps)
    starts = np.arange(0, n, n_action_steps, dtype=np.int32)
    before = np.concatenate([[spilled_before], counts])
    ends = np.minimum(starts + n_action_steps, n)
    return starts, before[ends] > before[starts]


def horizon_labels(spill_steps: np.ndarray, chunk_start: np.ndarray) -> np.ndarray:
    """(C,) bool: a particle that is spilled when the load has been delivered left at or after each
    chunk's first step.

    spill_steps: (K,) for each particle spilled at the end of the horizon (outside both bowls and
    off the spoon once the scoop, lift, carry, pour and settling are over), the action step at
    which it was last counted spilled (`SpillTracker.spill_steps`); chunk_start: (C,) step indices
    of the same episode. Judged on where particles end, not on the spilled count's rises: food in
    flight from the spoon to the target is outside both bowls for a few steps of every pour, and a
    count that rises and falls back is delivered food, not a spill.
    """
    steps = np.asarray(spill_steps, dtype=np.int64).reshape(-1)
    starts = np.asarray(chunk_start, dtype=np.int64).reshape(-1)
    if len(starts) and starts.min() < 0:
        raise ValueError(f"chunk starts {starts.tolist()} must be non-negative step indices")
    last = steps.max() if len(steps) else -1
    return starts <= last
