"""Spill labels of a spillage episode's chunks, from the spilled count after every step.

Two labels per chunk (docs/datasets.md, "Two labels"):
- chunk (the paper's): did the spilled count rise while the chunk's own `n_action_steps` actions ran;
- horizon: did food spill at any step from the chunk's first action until the load was delivered
  (the rest of the scoop, the lift, the carry and the pour), so a dig that heaps the spoon is
  blamed for the heap it sheds later.
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


def horizon_labels(spilled_until_delivery: np.ndarray, chunk_start: np.ndarray, spilled_before: int = 0) -> np.ndarray:
    """(C,) bool: the spilled count rose at some step from each chunk's first step to the last one.

    spilled_until_delivery: (S,) the spilled count after every step from the episode's first
    action until the load was delivered (scoop, lift, carry, pour and settling); chunk_start: (C,)
    step indices into it; spilled_before: the count before the first step. A rise, not a net
    gain: food that reaches the target bowl leaves the count, so the count can fall.
    """
    counts = np.asarray(spilled_until_delivery, dtype=np.int64)
    rises = np.diff(np.concatenate([[spilled_before], counts])) > 0  # rises[t]: step t spilled
    # spill_from[t]: some step >= t spilled (a reversed running OR)
    spill_from = np.concatenate([np.logical_or.accumulate(rises[::-1])[::-1], [False]])
    starts = np.asarray(chunk_start, dtype=np.int64)
    if len(starts) and (starts.min() < 0 or starts.max() >= max(len(counts), 1)):
        raise ValueError(f"chunk starts {starts.tolist()} lie outside the {len(counts)} recorded steps")
    return spill_from[starts].astype(bool)
