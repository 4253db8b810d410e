"""Tiny spillage datasets in the real on-disk format, built with grits_lab.data.format.write_episode."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from grits_lab.data.format import MANIFEST_FILE, rebuild_index, write_episode
from grits_lab.geometry import matrix_to_rot6d
from grits_lab.sim.foods import SHAPES

BOWL_CENTRE = np.array([0.5, 0.0, 0.05])


def write_tiny_spillage_dataset(root: Path, n_episodes: int = 12, n_points: int = 48, n_chunks: int = 3, seed: int = 0, n_action_steps: int = 12,
                                horizon: bool = False, spill_below: float = 0.015) -> Path:
    """Episodes whose chunk label depends on trajectory and cloud together: a chunk spills when
    the spoon dips deeper than `spill_below` (1.5 cm; of dips up to 5 cm) below the top of the food pile. With `horizon`, also the
    horizon labels: every third episode sheds its load in a carry after the last chunk, so all its
    chunks are horizon-positive; otherwise a chunk is horizon-positive when it or a later one spilled."""
    rng = np.random.default_rng(seed)
    root.mkdir(parents=True, exist_ok=True)
    (root / MANIFEST_FILE).write_text(yaml.safe_dump({"format_version": 1, "kind": "spillage"}))
    rot = matrix_to_rot6d(np.eye(3))
    for e in range(n_episodes):
        food_top = BOWL_CENTRE[2] + rng.uniform(0.0, 0.04)
        t = n_chunks * n_action_steps - 4  # the last chunk is short: exercises padding
        depth = rng.uniform(-0.05, 0.02, size=n_chunks)
        z = np.repeat(food_top + depth, n_action_steps)[:t]
        xyz = np.stack([BOWL_CENTRE[0] + rng.uniform(-0.03, 0.03, t), BOWL_CENTRE[1] + rng.uniform(-0.03, 0.03, t), z], 1)
        trajectory = np.concatenate([xyz, np.repeat(rot[None], t, 0)], 1).astype(np.float32)
        starts = np.arange(n_chunks, dtype=np.int32) * n_action_steps
        spilled = np.array([trajectory[s : s + n_action_steps, 2].min() < food_top - spill_below for s in starts])
        clouds = []
        for c in range(n_chunks):
            food = BOWL_CENTRE + rng.uniform([-0.05, -0.05, 0.0], [0.05, 0.05, food_top - BOWL_CENTRE[2]], (n_points, 3))
            spoon = trajectory[starts[c], :3] + rng.normal(0, 0.01, (n_points, 3))
            ang = rng.uniform(0, 2 * np.pi, n_points)
            bowl = BOWL_CENTRE + np.stack([0.085 * np.cos(ang), 0.085 * np.sin(ang), rng.uniform(-0.03, 0.035, n_points)], 1)
            clouds.append(np.stack([food, spoon, bowl]))
        cloud = np.asarray(clouds, dtype=np.float16)
        raw = (cloud + rng.normal(0, 0.002, cloud.shape)).astype(np.float16)
        arrays = {"trajectory": trajectory, "chunk_start": starts, "chunk_cloud": cloud, "chunk_cloud_raw": raw, "chunk_spilled": spilled, "spilled_over_time": np.cumsum(np.repeat(spilled, n_action_steps)[:t]).astype(np.int32)}
        meta = {"shape": SHAPES[e % 4], "seed": seed * 1000 + e, "label": int(spilled.any()), "split": "train"}
        if horizon:
            later = np.logical_or.accumulate(spilled[::-1])[::-1]
            arrays["chunk_spilled_horizon"] = later | (e % 3 == 0)
            meta["label_horizon"] = int(arrays["chunk_spilled_horizon"].any())
        write_episode(root, f"ep_{e:06d}", arrays, meta)
    rebuild_index(root)
    return root


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory) -> Path:
    return write_tiny_spillage_dataset(tmp_path_factory.mktemp("spill") / "tiny")


@pytest.fixture(scope="session")
def tiny_horizon_dataset(tmp_path_factory) -> Path:
    """As `tiny_dataset`, with horizon labels (chunk_spilled_horizon, label_horizon)."""
    return write_tiny_spillage_dataset(tmp_path_factory.mktemp("spill") / "tiny_horizon", horizon=True)
