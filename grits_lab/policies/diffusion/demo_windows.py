"""Demonstration windows for the diffusion policy: (observation history, action horizon) pairs.

Episodes (contract 4) are read one file at a time, only the keys the policy needs, with clouds
cut to `cache_points_per_object` random points per object (fixed per episode and seed) so that
80 demonstrations fit in memory; batches are then gathered with numpy indexing.

For a current step c of an episode with T steps, the window holds observations at
c - n_obs_steps + 1 ... c and actions at c - n_obs_steps + 1 ... c - n_obs_steps + horizon;
indices outside [0, T - 1] repeat the first or last entry (the robot at rest before the start
and holding its final pose after the end), as Diffusion Policy's padded sampler does; an action
before the start is the first measured pose, where the resting spoon was commanded to stay.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
import numpy as np
from tqdm import tqdm

from grits_lab.data.format import INDEX_FILE, load_index, read_episode, require_finite
from grits_lab.errors import InputError, StorageError
from grits_lab.policies.diffusion.configuration_diffusion import DiffusionPolicyConfig


@dataclass
class EpisodeArrays:
    episode_id: str
    arrays: dict[str, np.ndarray]  # action (T, 9), ee_pose (T, 9), cloud (T, 3, n, 3) / rgbd (...)

    @property
    def length(self) -> int:
        return int(self.arrays["action"].shape[0])


def split_demo_episodes(episode_ids: list[str], val_fraction: float, seed: int) -> tuple[list[str], list[str]]:
    """Hold out about `val_fraction` of the episodes, chosen by hash (stable as episodes are added)."""
    if val_fraction <= 0 or len(episode_ids) < 2:
        return sorted(episode_ids), []
    score = lambda e: int.from_bytes(hashlib.blake2b(f"{seed}|{e}".encode(), digest_size=8).digest(), "little")
    ranked = sorted(episode_ids, key=score)
    n_val = min(len(ranked) - 1, max(1, round(val_fraction * len(ranked))))
    return sorted(ranked[n_val:]), sorted(ranked[:n_val])


def dataset_fingerprint(dataset_dir: str | Path) -> str:
    """Hash of the episode files' names and sizes: tells a checkpoint which data it was trained on."""
    digest = hashlib.sha256()
    for path in sorted((Path(dataset_dir) / "episodes").glob("*.npz")):
        digest.update(f"{path.name}:{path.stat().st_size};".encode())
    return digest.hexdigest()[:16]


def list_demo_episodes(dataset_dir: str | Path, splits: tuple[str, ...] = ("train",)) -> list[str]:
    """Episode ids of a demonstration dataset, filtered by the meta `split` when the index has one."""
    index = load_index(dataset_dir)
    if len(index) == 0:
        raise StorageError(f"dataset {dataset_dir} has no episodes")
    if splits and "split" in index.columns:
        index = index[index["split"].isin(list(splits))]
    if len(index) == 0:
        raise StorageError(f"dataset {dataset_dir} has no episodes in splits {list(splits)} (see {INDEX_FILE})")
    return sorted(index["episode_id"].astype(str).tolist())


class DemoWindowDataset:
    """In-memory windows over demonstration episodes, sampled uniformly over (episode, step)."""

    def __init__(
        self,
        dataset_dir: str | Path,
        episode_ids: list[str],
        config: DiffusionPolicyConfig,
        cache_points_per_object: int = 512,
        seed: int = 0,
        progress: bool = True,
    ) -> None:
        self.config = config
        kind = config.obs_encoder.kind
        keys = ["action", "ee_pose"] + (["cloud"] if kind == "pointcloud" else ["rgbd"] if kind == "rgbd" else [])
        self.keys = keys
        rng = np.random.default_rng(seed)
        self.episodes: list[EpisodeArrays] = []
        for episode_id in tqdm(episode_ids, desc="loading episodes", disable=not progress, leave=False):
            path = Path(dataset_dir) / "episodes" / f"{episode_id}.npz"
            available = _array_names(path)
            missing = [k for k in keys if k not in available]
            if missing:
                raise StorageError(f"episode {episode_id} lacks {missing}, needed by obs_encoder.kind={kind!r}")
            arrays, _ = read_episode(path, keys=keys)
            require_finite(arrays, path)
            self._check(episode_id, arrays)
            if "cloud" in arrays:
                n = arrays["cloud"].shape[2]
                m = min(n, max(cache_points_per_object, config.obs_encoder.points_per_object))
                idx = np.sort(rng.choice(n, size=m, replace=False)) if m < n else np.arange(n)
                arrays["cloud"] = np.ascontiguousarray(arrays["cloud"][:, :, idx]).astype(np.float16)
            self.episodes.append(EpisodeArrays(episode_id, arrays))
        if not self.episodes:
            raise InputError("no episodes to train on")
        lengths = np.array([e.length for e in self.episodes])
        self.window_episode = np.repeat(np.arange(len(lengths)), lengths)
        self.window_step = np.concatenate([np.arange(n) for n in lengths])

    def __len__(self) -> int:
        return int(self.window_step.shape[0])

    @staticmethod
    def _check(episode_id: str, arrays: dict[str, np.ndarray]) -> None:
        t = arrays["action"].shape[0]
        if arrays["action"].ndim != 2 or arrays["action"].shape[1] != 9 or t == 0:
            raise StorageError(f"episode {episode_id}: `action` must be (T, 9); got {arrays['action'].shape}")
        for key, value in arrays.items():
            if value.shape[0] != t:
                raise StorageError(f"episode {episode_id}: `{key}` has {value.shape[0]} steps, `action` has {t}")
            if np.issubdtype(value.dtype, np.floating) and not np.all(np.isfinite(value)):
                raise StorageError(f"episode {episode_id}: `{key}` contains NaN or inf")

    def all_actions(self) -> np.ndarray:
        return np.concatenate([e.arrays["action"] for e in self.episodes])

    def all_poses(self) -> np.ndarray:
        return np.concatenate([e.arrays["ee_pose"] for e in self.episodes])

    def all_cloud_points(self, max_points: int = 200_000, seed: int = 0) -> np.ndarray | None:
        if "cloud" not in self.keys:
            return None
        points = np.concatenate([e.arrays["cloud"].reshape(-1, 3) for e in self.episodes]).astype(np.float32)
        if len(points) > max_points:
            points = points[np.random.default_rng(seed).choice(len(points), max_points, replace=False)]
        return points

    def window(self, index: int) -> dict[str, np.ndarray]:
        return self.gather(np.array([index]))

    def gather(self, indices: np.ndarray) -> dict[str, np.ndarray]:
        """Batch of windows: `action` (B, horizon, 9), `ee_pose` (B, n_obs, 9), `cloud`/`rgbd` (B, n_obs, ...)."""
        cfg = self.config
        batch: dict[str, list[np.ndarray]] = {k: [] for k in self.keys}
        obs_offsets = np.arange(-cfg.n_obs_steps + 1, 1)
        act_offsets = np.arange(-cfg.n_obs_steps + 1, -cfg.n_obs_steps + 1 + cfg.horizon)
        for i in indices:
            ep = self.episodes[self.window_episode[i]]
            c = self.window_step[i]
            last = ep.length - 1
            act_idx = c + act_offsets
            actions = ep.arrays["action"][np.clip(act_idx, 0, last)]
            if act_idx[0] < 0:  # before the first action the spoon rests where it started
                actions[act_idx < 0] = ep.arrays["ee_pose"][0]
            batch["action"].append(actions)
            obs_idx = np.clip(c + obs_offsets, 0, last)
            for key in self.keys[1:]:
                batch[key].append(ep.arrays[key][obs_idx])
        return {k: np.stack(v) for k, v in batch.items()}

    def batch_indices(self, step: int, batch_size: int, seed: int) -> np.ndarray:
        """Window indices of training step `step`: epoch-wise shuffles, determined by (seed, step) alone.

        Deriving the order from the step (not from a running generator) makes a resumed run
        draw exactly the batches the uninterrupted run would have drawn.
        """
        n = len(self)
        batch_size = min(batch_size, n)
        per_epoch = n // batch_size
        epoch, position = divmod(step, per_epoch)
        order = np.random.default_rng([seed, epoch]).permutation(n)
        return order[position * batch_size : (position + 1) * batch_size]

def _array_names(path: Path) -> set[str]:
    """Names of the arrays in an episode file, without decompressing them."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return set(data.files)
    except (OSError, ValueError) as exc:
        raise StorageError(f"corrupted or unreadable episode file {path}: {exc}") from None
