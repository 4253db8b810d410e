"""Chunk-level training samples streamed from a spillage dataset (contract 4, kind "spillage").

One sample = (trajectory[chunk_start[c] : chunk_start[c] + L] normalized, chunk_cloud[c]
normalized, label[c]): the L = 12 actions the policy is about to execute, the cloud observed when
the chunk starts, and the chunk's label of the kind asked for (grits_lab/data/chunk_labels.py):
`chunk_spilled` (the count rose during the chunk) or `chunk_spilled_horizon` (food spilled from
its first action until the load was delivered). Episodes
are split into train and validation by episode (never by chunk: chunks of one episode share a
scene, and splitting them would leak it), optionally holding out one particle shape.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch
from torch.utils.data import IterableDataset

from grits_lab.config import load_yaml
from grits_lab.data.chunk_labels import LABEL_ARRAYS, TRIAL_LABELS
from grits_lab.data.format import (
    CHUNK_KEY,
    EPISODE_DIR,
    MANIFEST_FILE,
    RETIRED_CHUNK_KEY,
    load_index,
    read_episode,
    refuse_retired_chunk_key,
    require_finite,
)
from grits_lab.data.normalize import ActionNormalizer
from grits_lab.errors import ConfigError, InputError, StorageError
from grits_lab.seeding import derive_seed, make_rng
from grits_lab.spillage.model import CloudNormalizer

CLOUD_KEYS = {"composite": "chunk_cloud", "raw": "chunk_cloud_raw"}
REQUIRED = ("trajectory", "chunk_start", "chunk_spilled")


@dataclass
class EpisodeSplit:
    """Episode files (relative to the dataset directory) of the training and validation sets."""

    train: list[str]
    val: list[str]


def check_spillage_dataset(dataset_dir: str | Path, n_action_steps: int | None = None, key: str = "model.n_action_steps",
                           label: str = "chunk", label_key: str = "data.label") -> Any:
    """The dataset's index (DataFrame) after checking that it exists, is of kind "spillage",
    given `n_action_steps`, that its labels judge chunks of that many actions (ConfigError naming `key`),
    and that it holds the `label` asked for (ConfigError naming `label_key`).
    A dataset that calls the chunk length `chunk_len` (collected before scoop-v4) is refused naming that key."""
    dataset_dir = Path(dataset_dir)
    try:
        present = (dataset_dir / EPISODE_DIR).is_dir()
    except OSError as exc:  # a name the file system refuses (too long, ...): is_dir only absorbs "not found"
        raise StorageError(f"no spillage dataset at {str(dataset_dir)[:80]}: {exc.strerror}") from None
    if not present:
        raise StorageError(f"no spillage dataset at {dataset_dir} (missing {EPISODE_DIR}/); collect one first")
    manifest_path = dataset_dir / MANIFEST_FILE
    manifest = load_yaml(manifest_path) if manifest_path.exists() else {}
    if manifest_path.exists():
        kind = manifest.get("kind")
        if kind != "spillage":
            raise InputError(f"{dataset_dir} is a dataset of kind {kind!r}; the predictor trains on kind 'spillage'")
    stored = manifest.get("config") if isinstance(manifest.get("config"), dict) else {}
    remedy = "collect the dataset again under the current protocol"
    refuse_retired_chunk_key(stored, manifest_path, RETIRED_CHUNK_KEY, remedy)
    index = load_index(dataset_dir)
    refuse_retired_chunk_key(index.columns, dataset_dir / EPISODE_DIR, RETIRED_CHUNK_KEY, remedy)  # the episodes' meta
    if len(index) == 0:
        raise StorageError(f"the spillage dataset at {dataset_dir} holds no episodes")
    if n_action_steps is not None:
        collected = {int(v) for v in index[CHUNK_KEY].dropna().unique()} if CHUNK_KEY in index.columns else set()
        if not collected and CHUNK_KEY in stored:
            collected = {int(stored[CHUNK_KEY])}
        if collected and collected != {n_action_steps}:
            raise ConfigError(
                f"`{key}` is {n_action_steps}, but the spillage dataset at {dataset_dir} was collected with "
                f"n_action_steps {', '.join(map(str, sorted(collected)))}: its labels judge chunks of that many actions"
            )
    if TRIAL_LABELS[label] not in index.columns or index[TRIAL_LABELS[label]].isna().any():
        raise ConfigError(
            f"`{label_key}` is {label}, but the spillage dataset at {dataset_dir} has episodes without "
            f"{LABEL_ARRAYS[label]} (collected before horizon labels); collect it again or use label chunk"
        )
    return index


def split_spillage_episodes(index: Any, val_fraction: float, seed: int, holdout_shape: str | None = None) -> EpisodeSplit:
    """Split by episode: a seeded random `val_fraction`, or every episode of `holdout_shape`."""
    files = sorted(index["file"].tolist())
    if holdout_shape is not None:
        if "shape" not in index.columns:
            raise InputError("`data.holdout_shape` is set but the dataset's index has no `shape` column")
        shapes = dict(zip(index["file"], index["shape"]))
        known = sorted(set(map(str, shapes.values())))
        if holdout_shape not in known:
            raise InputError(f"`data.holdout_shape` {holdout_shape!r} is not in the dataset (shapes: {', '.join(known)})")
        val = [f for f in files if shapes[f] == holdout_shape]
        train = [f for f in files if shapes[f] != holdout_shape]
    else:
        order = make_rng(derive_seed(seed, "predictor-split")).permutation(len(files))
        n_val = max(1, int(round(val_fraction * len(files))))
        if n_val >= len(files):
            raise InputError(f"the dataset has {len(files)} episode(s): too few to split off a validation set")
        val = sorted(files[i] for i in order[:n_val])
        train = sorted(files[i] for i in order[n_val:])
    if not train or not val:
        raise InputError("the train/validation split left one side empty")
    return EpisodeSplit(train=train, val=val)


def refuse_listed_twice(dataset_dirs: list[Path], key: str) -> None:
    """InputError naming `key` when two entries of `dataset_dirs` are one directory under any
    spelling (a trailing slash, `./`, a link to it); call it once every entry is known to exist."""
    seen = [d.resolve() for d in dataset_dirs]
    for i, (again, resolved) in enumerate(zip(dataset_dirs, seen)):
        if resolved in seen[:i]:
            first = dataset_dirs[seen.index(resolved)]
            spelled = "" if str(first) == str(again) else f" (again as {again})"
            raise InputError(f"{key} lists {first} twice{spelled}; each dataset once")


def split_training_datasets(dataset_dirs: list[Path], val_fraction: float, seed: int, holdout_shape: str | None = None,
                            **check: Any) -> tuple[Path, EpisodeSplit]:
    """The directory a training run's episode files are relative to, and its train/validation split,
    over one spillage dataset or several (`data.dataset` as a list).

    Each dataset is checked (`check_spillage_dataset(dir, **check)`) and split on its own by
    `split_spillage_episodes` with the same `val_fraction`, `seed` and `holdout_shape`, so the
    episodes a dataset holds out are the ones it holds out when trained alone, and a predictor
    trained on several can be scored on one dataset's validation episodes beside a predictor trained
    on that dataset only. One dataset: its directory and files relative to it. Several: the current
    directory and each file prefixed with its dataset's path. Errors name the dataset they concern;
    a dataset listed twice is an InputError.
    """
    if len(dataset_dirs) == 1:
        index = check_spillage_dataset(dataset_dirs[0], **check)
        return dataset_dirs[0], split_spillage_episodes(index, val_fraction, seed, holdout_shape)
    indexes = [check_spillage_dataset(d, **check) for d in dataset_dirs]  # each exists: it resolves
    refuse_listed_twice(dataset_dirs, "`data.dataset`")
    train: list[str] = []
    val: list[str] = []
    for d, index in zip(dataset_dirs, indexes):
        try:
            part = split_spillage_episodes(index, val_fraction, seed, holdout_shape)
        except InputError as exc:
            raise InputError(f"{d}: {exc}") from None
        train += [str(d / f) for f in part.train]
        val += [str(d / f) for f in part.val]
    return Path("."), EpisodeSplit(train=train, val=val)


def load_chunks(path: Path, cloud_key: str, label_key: str = "chunk_spilled") -> dict[str, np.ndarray]:
    """The arrays one episode contributes, checked for presence and consistent chunk counts;
    "label" is the `label_key` array (chunk_spilled or chunk_spilled_horizon)."""
    arrays, _ = read_episode(path, keys=None)
    missing = [k for k in (*REQUIRED, label_key, cloud_key) if k not in arrays]
    if missing:
        raise StorageError(f"{path}: spillage episode lacks {', '.join(missing)}")
    n_chunks = len(arrays["chunk_start"])
    if len(arrays[label_key]) != n_chunks or len(arrays[cloud_key]) != n_chunks:
        raise StorageError(f"{path}: chunk_start, {label_key} and {cloud_key} differ in length")
    require_finite(arrays, path, ("trajectory", cloud_key))
    return {
        "trajectory": arrays["trajectory"].astype(np.float32),
        "chunk_start": arrays["chunk_start"].astype(np.int64),
        "label": arrays[label_key].astype(bool),
        "cloud": arrays[cloud_key],
    }


def trajectory_window(trajectory: np.ndarray, start: int, length: int) -> np.ndarray:
    """trajectory[start : start + length], padded with the last pose (the arm holds still after the end)."""
    window = trajectory[start : start + length]
    if len(window) == 0:
        raise StorageError(f"chunk start {start} lies beyond the trajectory's {len(trajectory)} waypoints")
    if len(window) < length:
        window = np.concatenate([window, np.repeat(window[-1:], length - len(window), axis=0)])
    return window


def subsample_points(cloud: np.ndarray, n: int | None, rng: np.random.Generator) -> np.ndarray:
    """A random subset of `n` points per object from `cloud` (K, N, 3) (all points when n is None or >= N)."""
    if n is None or n >= cloud.shape[1]:
        return cloud
    idx = np.stack([rng.choice(cloud.shape[1], n, replace=False) for _ in range(cloud.shape[0])])
    return np.take_along_axis(cloud, idx[:, :, None], axis=1)


def fit_normalizers(dataset_dir: Path, files: list[str], cloud_key: str, scale: float, max_cloud_episodes: int = 64) -> tuple[ActionNormalizer, CloudNormalizer]:
    """Action normalizer on every training waypoint; cloud centre on the bowl points of a few training clouds."""
    trajectories = []
    for f in files:
        arrays = read_episode(dataset_dir / f, keys=["trajectory"])[0]
        require_finite(arrays, dataset_dir / f)
        trajectories.append(arrays["trajectory"])
    action = ActionNormalizer().fit(np.concatenate(trajectories, axis=0))
    step = max(1, len(files) // max_cloud_episodes)
    clouds = [read_episode(dataset_dir / f, keys=[cloud_key])[0][cloud_key][:1].astype(np.float32) for f in files[::step]]
    cloud = CloudNormalizer(scale=scale).fit(np.concatenate(clouds, axis=0))
    return action, cloud


class SpillageChunkDataset(IterableDataset):
    """Streams `(traj_norm (L, 9), cloud_norm (3, n, 3), label)` samples episode by episode; the
    label is the `label_key` array's (chunk_spilled, the default, or chunk_spilled_horizon).

    With `shuffle`, the episode order and a shuffle buffer of `buffer_size` samples are drawn
    afresh each epoch (call `set_epoch`), and so are the point subsets; without it the order and
    the subsets are fixed, so a validation score is the same every time it is computed.
    """

    def __init__(
        self,
        dataset_dir: str | Path,
        files: list[str],
        *,
        cloud_key: str,
        n_action_steps: int,
        action_normalizer: ActionNormalizer,
        cloud_normalizer: CloudNormalizer,
        points_per_object: int | None,
        shuffle: bool,
        seed: int = 0,
        cache: bool = True,
        buffer_size: int = 2048,
        label_key: str = "chunk_spilled",
    ) -> None:
        self.dataset_dir = Path(dataset_dir)
        self.files = list(files)
        self.cloud_key = cloud_key
        self.n_action_steps = n_action_steps
        self.action_normalizer = action_normalizer
        self.cloud_normalizer = cloud_normalizer
        self.points_per_object = points_per_object
        self.shuffle = shuffle
        self.seed = seed
        self.cache = cache
        self.buffer_size = buffer_size
        self.label_key = label_key
        self.epoch = 0
        self._cache: dict[str, dict[str, np.ndarray]] = {}

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def _episode(self, file: str) -> dict[str, np.ndarray]:
        if file in self._cache:
            return self._cache[file]
        chunks = load_chunks(self.dataset_dir / file, self.cloud_key, self.label_key)
        if self.cache:
            self._cache[file] = chunks
        return chunks

    def _samples(self, file: str, rng: np.random.Generator) -> Iterator[tuple[torch.Tensor, torch.Tensor, int]]:
        ep = self._episode(file)
        traj_norm = self.action_normalizer.normalize(ep["trajectory"]).astype(np.float32)
        for c, start in enumerate(ep["chunk_start"]):
            window = trajectory_window(traj_norm, int(start), self.n_action_steps)
            cloud = subsample_points(ep["cloud"][c].astype(np.float32), self.points_per_object, rng)
            yield (
                torch.from_numpy(np.ascontiguousarray(window)),
                torch.from_numpy(self.cloud_normalizer.normalize(cloud)),
                int(ep["label"][c]),
            )

    def __iter__(self) -> Iterator[tuple[torch.Tensor, torch.Tensor, int]]:
        if not self.shuffle:
            for file in self.files:
                yield from self._samples(file, make_rng(derive_seed(self.seed, "points", file)))
            return
        rng = make_rng(derive_seed(self.seed, "epoch", self.epoch))
        buffer: list[tuple[torch.Tensor, torch.Tensor, int]] = []
        for i in rng.permutation(len(self.files)):
            for sample in self._samples(self.files[i], rng):
                if len(buffer) < self.buffer_size:
                    buffer.append(sample)
                    continue
                j = int(rng.integers(len(buffer)))
                yield buffer[j]
                buffer[j] = sample
        rng.shuffle(buffer)  # type: ignore[arg-type]
        yield from buffer

    def _chunk_labels(self) -> list[np.ndarray]:
        """Each file's chunk labels, in file order (reads only the label arrays)."""
        return [read_episode(self.dataset_dir / f, keys=[self.label_key])[0][self.label_key].astype(bool) for f in self.files]

    def sample_episodes(self) -> np.ndarray:
        """The episode file of every sample in the unshuffled order."""
        return np.repeat(np.asarray(self.files, dtype=object), [len(c) for c in self._chunk_labels()])

    def labels(self) -> np.ndarray:
        """Every sample's label in the unshuffled order."""
        out = self._chunk_labels()
        return np.concatenate(out) if out else np.zeros(0, dtype=bool)
