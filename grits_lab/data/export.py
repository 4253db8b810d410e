"""Export a demonstration dataset to the formats other training code reads: LeRobot and zarr.

`grits-lab dataset export DIR --format lerobot|zarr --output OUT` (grits_lab/cli/dataset_export.py).
Only demonstrations (`kind: demos`) hold per-step observations and actions; spillage trials and
rollout chunks are chunk-level and are refused. Every per-step array of an episode has one row per
action step t (T rows): `action` (T, 9) the commanded pose (xyz + 6-D rotation, metres), `ee_pose`
(T, 9) the pose measured before that action, `joint_pos` (T, 7) radians, `cloud` (T, 3, n, 3) the
composite cloud (objects in `CLOUD_OBJECTS` order, metres), `rgbd` (T, cams, 4, H, W) when images
were recorded, and `spilled_over_time` (T,) particles spilled after the step.

Formats (each an optional extra of the package):

- ``zarr`` (``pip install "grits-lab[zarr]"``): the layout of diffusion_policy's ``ReplayBuffer``
  (real-stanford/diffusion_policy, ``diffusion_policy/common/replay_buffer.py``): a zarr v2 group
  with ``data/<key>`` holding every episode's rows concatenated along axis 0 under grits_lab's
  names and dtypes, and ``meta/episode_ends`` (int64, cumulative row counts), so
  ``ReplayBuffer.copy_from_path(OUT)`` loads it. The group's attributes name each episode's id,
  food and level and the control rate.
- ``lerobot`` (``pip install "grits-lab[lerobot]"``): a ``LeRobotDataset`` written with lerobot's
  own writer (``LeRobotDataset.create``, ``add_frame``, ``save_episode``, ``finalize``), so the
  export is in the format version of the installed lerobot. Keys follow lerobot's convention:
  ``action``, ``observation.state`` (= ``ee_pose``), ``observation.joint_pos``,
  ``observation.pointcloud`` (= ``cloud``, float32), ``observation.rgbd`` (float32, when present)
  and ``next.spilled`` (= ``spilled_over_time``); the task of an episode is "scoop <level> <food>"
  and the frame rate is the dataset's `control_hz`. ``meta/grits_lab.json`` names each episode's
  id, food and level.

The export is written beside OUT and renamed into place when complete: a reader never sees half
an export, and an interrupted export leaves nothing to clean up but a hidden temporary folder.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from grits_lab.config import parse_yaml
from grits_lab.data.format import MANIFEST_FILE, load_index, read_episode, require_finite
from grits_lab.errors import InputError, StorageError

EXPORT_FORMATS = ("lerobot", "zarr")
STEP_KEYS = ("action", "ee_pose", "joint_pos", "cloud", "rgbd", "spilled_over_time")
# grits_lab's name -> lerobot's feature name (lerobot's `observation.*` / `next.*` convention).
LEROBOT_KEYS = {
    "action": "action",
    "ee_pose": "observation.state",
    "joint_pos": "observation.joint_pos",
    "cloud": "observation.pointcloud",
    "rgbd": "observation.rgbd",
    "spilled_over_time": "next.spilled",
}
POSE_NAMES = ["x", "y", "z", "r11", "r21", "r31", "r12", "r22", "r32"]  # xyz + the first two rotation columns
EXTRA_OF = {"lerobot": "lerobot", "zarr": "zarr"}


def export_dataset(dataset_dir: str | Path, fmt: str, output: str | Path, repo_id: str | None = None) -> dict[str, Any]:
    """Write the demonstration dataset at `dataset_dir` to `output` in format `fmt`; return a summary.

    Raises InputError (before writing anything) for an unknown format, a missing optional
    library, an existing `output`, or a dataset that is not a demonstration dataset; StorageError
    for a damaged episode file or an episode whose per-step arrays disagree in length.
    """
    if fmt not in EXPORT_FORMATS:
        raise InputError(f"--format must be one of {', '.join(EXPORT_FORMATS)}. Got {fmt!r}.")
    dataset_dir, output = Path(dataset_dir), Path(output)
    manifest = _demos_manifest(dataset_dir)
    if output.exists():
        raise InputError(f"--output {output} already exists; remove it or name another folder")
    _require_library(fmt)
    index = load_index(dataset_dir)
    if len(index) == 0:
        raise StorageError(f"dataset {dataset_dir} has no episodes")
    index = index.sort_values("episode_id", kind="stable").reset_index(drop=True)
    info = {
        "source": str(dataset_dir),
        "protocol": manifest.get("protocol"),
        "fps": control_hz(manifest, dataset_dir),
        "episode_ids": [str(e) for e in index["episode_id"]],
        "food": [str(v) for v in index.get("food", [""] * len(index))],
        "level": [str(v) for v in index.get("level", [""] * len(index))],
    }
    episodes = (step_arrays(dataset_dir / str(f)) for f in index["file"])
    writer: Callable[..., int] = _write_zarr if fmt == "zarr" else _write_lerobot
    output.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{output.name}.", suffix=".tmp", dir=output.parent))
    try:
        frames = writer(staging / "export", episodes, info, repo_id or f"grits_lab/{dataset_dir.name}")
        (staging / "export").rename(output)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return {"output": str(output), "format": fmt, "episodes": len(index), "frames": int(frames), "fps": info["fps"]}


def step_arrays(path: Path) -> dict[str, np.ndarray]:
    """The per-step arrays of one episode file (those of `STEP_KEYS` it holds), checked for one length."""
    arrays, _ = read_episode(path)
    arrays = {k: arrays[k] for k in STEP_KEYS if k in arrays}
    if "action" not in arrays:
        raise StorageError(f"{path}: no `action` array; only demonstrations hold per-step actions")
    require_finite(arrays, path)
    steps = len(arrays["action"])
    for key, value in arrays.items():
        if len(value) != steps:
            raise StorageError(f"{path}: `{key}` has {len(value)} rows but `action` has {steps}")
    return arrays


def control_hz(manifest: dict[str, Any], dataset_dir: Path) -> float:
    """The rate of the dataset's actions: its collection config's `sim.control_hz` (the default when unset)."""
    from grits_lab.config import config_from_dict
    from grits_lab.sim.sim_config import SimConfig

    config = manifest.get("config") if isinstance(manifest.get("config"), dict) else {}
    sim = config_from_dict(SimConfig, config.get("sim") or {}, f"{dataset_dir / MANIFEST_FILE}: config.sim")
    return float(sim.control_hz)


def _demos_manifest(dataset_dir: Path) -> dict[str, Any]:
    path = dataset_dir / MANIFEST_FILE
    if not path.is_file():
        raise InputError(f"not a grits-lab dataset (no {MANIFEST_FILE}): {dataset_dir}")
    manifest = parse_yaml(path.read_text(), path) or {}
    if manifest.get("kind") != "demos":
        raise InputError(f"{path}: `kind` is {manifest.get('kind')!r}; only demonstration datasets (kind: demos) "
                         "hold per-step observations and actions to export")
    return manifest


def _require_library(fmt: str) -> None:
    try:
        if fmt == "zarr":
            import numcodecs  # noqa: F401
            import zarr  # noqa: F401
        else:
            from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: F401
    except ImportError as exc:
        raise InputError(f"--format {fmt} needs the `{EXTRA_OF[fmt]}` extra ({exc}); "
                         f"pip install \"grits-lab[{EXTRA_OF[fmt]}]\"") from None


def _write_zarr(root_path: Path, episodes: Iterator[dict[str, np.ndarray]], info: dict[str, Any], repo_id: str) -> int:
    import numcodecs
    import zarr

    # diffusion_policy's ReplayBuffer default compressor; zarr v2 so that zarr 2 (its pin) reads it.
    compressor = numcodecs.Blosc(cname="lz4", clevel=5, shuffle=numcodecs.Blosc.NOSHUFFLE)
    root = zarr.open_group(str(root_path), mode="w", zarr_format=2)
    data, meta = root.require_group("data"), root.require_group("meta")
    ends: list[int] = []
    arrays: dict[str, Any] = {}
    for episode in episodes:
        start = ends[-1] if ends else 0
        steps = len(episode["action"])
        if arrays and set(episode) != set(arrays):
            raise StorageError(f"episode {info['episode_ids'][len(ends)]} holds {sorted(episode)}; "
                               f"the first episode holds {sorted(arrays)}")
        for key, value in episode.items():
            if key not in arrays:
                arrays[key] = data.create_array(key, shape=(0, *value.shape[1:]), dtype=value.dtype,
                                                chunks=(max(steps, 1), *value.shape[1:]), compressors=compressor)
            array = arrays[key]
            if array.shape[1:] != value.shape[1:]:
                raise StorageError(f"episode {info['episode_ids'][len(ends)]}: `{key}` is {value.shape[1:]} per step; "
                                   f"the first episode's is {array.shape[1:]}")
            array.resize((start + steps, *value.shape[1:]))
            array[start:start + steps] = value
        ends.append(start + steps)
    meta.create_array("episode_ends", data=np.asarray(ends, dtype=np.int64), chunks=(max(len(ends), 1),),
                      compressors=None)
    root.attrs.update({**info, "repo_id": repo_id, "layout": "diffusion_policy ReplayBuffer"})
    return ends[-1]


def _write_lerobot(root_path: Path, episodes: Iterator[dict[str, np.ndarray]], info: dict[str, Any], repo_id: str) -> int:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset = None
    frames = 0
    for i, episode in enumerate(episodes):
        values = {LEROBOT_KEYS[k]: _lerobot_value(k, v) for k, v in episode.items()}
        if dataset is None:
            dataset = LeRobotDataset.create(repo_id, fps=round(info["fps"]), root=root_path, robot_type="franka_panda",
                                            features=_lerobot_features(values), use_videos=False)
        task = f"scoop {info['level'][i]} {info['food'][i]}"
        for t in range(len(episode["action"])):
            dataset.add_frame({**{k: v[t] for k, v in values.items()}, "task": task})
        dataset.save_episode()
        frames += len(episode["action"])
    assert dataset is not None  # export_dataset refuses an empty dataset
    dataset.finalize()
    (root_path / "meta" / "grits_lab.json").write_text(json.dumps({**info, "keys": LEROBOT_KEYS}, indent=2))
    return frames


def _lerobot_value(key: str, value: np.ndarray) -> np.ndarray:
    """lerobot's frames are float32 (observations, actions) or int64 (counts), each step at least (1,)."""
    if key == "spilled_over_time":
        return value.astype(np.int64).reshape(-1, 1)
    return value.astype(np.float32)


def _lerobot_features(values: dict[str, np.ndarray]) -> dict[str, dict[str, Any]]:
    names = {"action": POSE_NAMES, "observation.state": POSE_NAMES,
             "observation.joint_pos": [f"joint_{j}" for j in range(7)], "next.spilled": ["particles"],
             "observation.pointcloud": ["object", "point", "xyz"], "observation.rgbd": ["camera", "channel", "height", "width"]}
    return {k: {"dtype": str(v.dtype), "shape": tuple(v.shape[1:]), "names": names[k]} for k, v in values.items()}
