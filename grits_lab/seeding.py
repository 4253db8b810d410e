"""Seeds as data: every episode's seed is derived from a root seed and the episode's identity."""

from __future__ import annotations

import hashlib

import numpy as np


def derive_seed(root_seed: int, *keys: object) -> int:
    """A 31-bit seed determined by `root_seed` and `keys` (food, level, index, ...).

    Hashing the keys (instead of adding offsets) keeps seeds stable when foods or levels are
    added to a sweep, so an episode keeps its seed across configs and can be replayed alone.
    """
    text = "|".join([str(int(root_seed))] + [str(k) for k in keys])
    digest = hashlib.blake2b(text.encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") & 0x7FFFFFFF


def make_rng(seed: int) -> np.random.Generator:
    """The one way grits_lab turns a seed into a random generator."""
    return np.random.default_rng(int(seed))
