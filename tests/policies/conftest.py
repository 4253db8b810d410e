"""Tiny demonstration datasets in the real on-disk format, written with grits_lab.data.format."""

import numpy as np
import pytest

from grits_lab.data.format import rebuild_index, write_episode
from grits_lab.geometry import quat_to_rot6d


def make_demo_episode(rng, level, T=24, n_points=64):
    """A scoop-like path whose dip depth follows the food level seen in the cloud."""
    s = np.linspace(0, 1, T)
    food_z = 0.05 + 0.03 * level
    x = 0.5 + 0.06 * np.sin(np.pi * s) + rng.normal(0, 0.001, T)
    y = 0.0 + 0.03 * s
    z = 0.25 - (0.25 - food_z) * np.sin(np.pi * s) ** 2
    angle = 0.6 * s
    quat = np.stack([np.sin(angle / 2), np.zeros(T), np.zeros(T), np.cos(angle / 2)], axis=1)
    action = np.concatenate([np.stack([x, y, z], 1), quat_to_rot6d(quat)], axis=1).astype(np.float32)
    ee_pose = np.concatenate([action[:1], action[:-1]]).astype(np.float32)  # measured before each action
    food = rng.normal([0.5, 0.0, food_z], [0.03, 0.03, 0.005], (T, n_points, 3))
    spoon = ee_pose[:, None, :3] + rng.normal(0, 0.01, (T, n_points, 3))
    bowl = rng.normal([0.5, 0.0, 0.03], [0.08, 0.08, 0.02], (T, n_points, 3))
    cloud = np.stack([food, spoon, bowl], axis=1).astype(np.float16)
    return {"action": action, "ee_pose": ee_pose, "joint_pos": np.zeros((T, 7), np.float32), "cloud": cloud}


def write_demo_dataset(path, n_episodes, seed=0, T=24):
    rng = np.random.default_rng(seed)
    for i in range(n_episodes):
        level = i % 3
        arrays = make_demo_episode(rng, level, T=T)
        write_episode(path, f"ep{i:03d}", arrays, {"food": "rice", "split": "train", "level": ["low", "mid", "high"][level], "seed": i})
    rebuild_index(path)
    return path


@pytest.fixture(scope="session")
def demo_dataset(tmp_path_factory):
    return write_demo_dataset(tmp_path_factory.mktemp("demos"), 6)


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    return write_demo_dataset(tmp_path_factory.mktemp("tiny"), 2, seed=1, T=16)
