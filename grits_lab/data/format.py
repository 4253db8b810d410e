"""On-disk dataset format (version 1): one compressed .npz per episode plus a rebuildable Parquet index.

Layout of a dataset directory::

    dataset.yaml          manifest: format_version, kind ("demos" or "spillage"), the task protocol
                          it was collected under (grits_lab/versions.py), the collection config
                          and its fingerprint
    episodes/<id>.npz     one episode; arrays plus a `meta` entry holding a JSON object
    index.parquet         one row per episode: the scalar entries of each episode's meta

Episode files are written atomically (temporary file + rename), so an interrupted collection
leaves only whole episodes; the index is always rebuilt from what is on disk, never trusted.
Composite point clouds store objects in the order of `CLOUD_OBJECTS`.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from grits_lab.errors import ConfigError, StorageError
from grits_lab.io import save_npz_atomic, save_parquet_atomic
from grits_lab.perception.composite import CLOUD_OBJECTS  # noqa: F401  (the order of stored cloud objects)

FORMAT_VERSION = 1
MANIFEST_FILE = "dataset.yaml"
INDEX_FILE = "index.parquet"
EPISODE_DIR = "episodes"
# A spillage dataset's chunk length is the policy's `n_action_steps`. Data and checkpoints stored
# before scoop-v4 call it `chunk_len`; readers refuse that name (`refuse_retired_chunk_key`), never
# read it (docs/migration.md).
CHUNK_KEY, RETIRED_CHUNK_KEY = "n_action_steps", "chunk_len"


def refuse_retired_chunk_key(names: Iterable[str], source: str | Path, key: str, remedy: str) -> None:
    """ConfigError naming `source` and `key` when `names` (a stored config's keys, an index's columns)
    hold the chunk length's retired name; `remedy` says what to do instead."""
    if RETIRED_CHUNK_KEY in names:
        raise ConfigError(f"{source}: `{key}` is the chunk length's name before scoop-v4, which this code "
                          f"no longer reads (it reads `{CHUNK_KEY}`); {remedy} (docs/migration.md)")


def episode_path(dataset_dir: str | Path, episode_id: str) -> Path:
    return Path(dataset_dir) / EPISODE_DIR / f"{episode_id}.npz"


def write_episode(dataset_dir: str | Path, episode_id: str, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> Path:
    """Write one episode atomically; `meta` must be JSON-serializable and carry `episode_id`."""
    if "meta" in arrays:
        raise ValueError("`meta` is reserved for the episode metadata")
    meta = {"episode_id": episode_id, "format_version": FORMAT_VERSION, **meta}
    path = episode_path(dataset_dir, episode_id)
    save_npz_atomic(path, **arrays, meta=np.array(json.dumps(meta, default=_json_default)))
    return path


def read_episode(path: str | Path, keys: Iterable[str] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Load an episode's arrays (all, or only `keys`) and its meta; a damaged file raises StorageError."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            names = [k for k in data.files if k != "meta"] if keys is None else list(keys)
            arrays = {k: data[k] for k in names}
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError, json.JSONDecodeError) as exc:
        raise StorageError(f"corrupted or unreadable episode file {path}: {exc}") from None
    return arrays, meta


def require_finite(arrays: dict[str, np.ndarray], path: str | Path, keys: Iterable[str] | None = None) -> None:
    """Refuse an episode whose floating arrays (all, or `keys`) hold NaN or infinity, naming the file."""
    for key in arrays if keys is None else keys:
        value = arrays[key]
        if np.issubdtype(value.dtype, np.floating):
            bad = int(value.size - np.count_nonzero(np.isfinite(value)))
            if bad:
                raise StorageError(f"{path}: `{key}` holds {bad} non-finite value(s) (NaN or inf); "
                                   "regenerate or remove this episode")


def read_meta(path: str | Path) -> dict[str, Any]:
    return read_episode(path, keys=())[1]


def verify_episode(path: str | Path) -> dict[str, Any]:
    """Check every array of an episode file against its stored checksum; return its meta.

    `read_meta` only decompresses the metadata, so a file damaged in one of its arrays would pass
    it; resuming jobs use this full check so that a damaged episode is regenerated, never used.
    """
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()
    except (OSError, zipfile.BadZipFile, EOFError, ValueError) as exc:
        raise StorageError(f"corrupted or unreadable episode file {path}: {exc}") from None
    if bad is not None:
        raise StorageError(f"corrupted episode file {path}: checksum mismatch in `{bad}`")
    return read_meta(path)


def list_episode_files(dataset_dir: str | Path) -> list[Path]:
    return sorted((Path(dataset_dir) / EPISODE_DIR).glob("*.npz"))


def rebuild_index(dataset_dir: str | Path, on_corrupt: str = "raise") -> "Any":
    """Scan the episode files, write index.parquet atomically and return it as a DataFrame.

    `on_corrupt`: "raise" stops at the first damaged file; "skip" leaves it out of the index
    (the caller reports it and may regenerate it).
    """
    import pandas as pd

    rows = []
    for path in list_episode_files(dataset_dir):
        try:
            meta = read_meta(path)
        except StorageError:
            if on_corrupt == "raise":
                raise
            continue
        row = {k: v for k, v in meta.items() if isinstance(v, (bool, int, float, str)) or v is None}
        row["file"] = str(path.relative_to(dataset_dir))
        rows.append(row)
    frame = pd.DataFrame(rows)
    save_parquet_atomic(Path(dataset_dir) / INDEX_FILE, frame)
    return frame


def load_index(dataset_dir: str | Path) -> "Any":
    """The dataset's index; rebuilt from the episode files when missing or unreadable."""
    import pandas as pd

    path = Path(dataset_dir) / INDEX_FILE
    if not Path(dataset_dir).is_dir():
        raise StorageError(f"dataset directory not found: {dataset_dir}")
    if not path.exists():
        return rebuild_index(dataset_dir)
    try:
        return pd.read_parquet(path)
    except Exception:  # pyarrow raises many types on a damaged file; the index only caches the episodes' meta
        return rebuild_index(dataset_dir)


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON-serializable: {type(value).__name__}")
