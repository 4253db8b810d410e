"""Episode datasets on disk: one file per episode plus a Parquet index, readable with numpy and pandas.

The storage layer: formats, indexes, summaries, normalizers fitted on stored arrays and the
trajectory arithmetic they use. It runs nothing; the jobs that fill datasets are in
grits_lab/collection.
"""

from grits_lab.data.chunk_labels import LABEL_ARRAYS, LABELS, TRIAL_LABELS, chunk_labels, horizon_labels
from grits_lab.data.format import (
    EPISODE_DIR,
    FORMAT_VERSION,
    INDEX_FILE,
    MANIFEST_FILE,
    episode_path,
    list_episode_files,
    load_index,
    read_episode,
    read_meta,
    rebuild_index,
    verify_episode,
    write_episode,
)
from grits_lab.data.info import dataset_summary, format_summary
from grits_lab.data.normalize import ActionNormalizer, MinMaxNormalizer
from grits_lab.data.trajectories import append_exit, as_pose9, mean_trajectory, resample, shift_trajectory

__all__ = [
    "ActionNormalizer",
    "EPISODE_DIR",
    "FORMAT_VERSION",
    "INDEX_FILE",
    "LABELS",
    "LABEL_ARRAYS",
    "MANIFEST_FILE",
    "MinMaxNormalizer",
    "TRIAL_LABELS",
    "append_exit",
    "as_pose9",
    "chunk_labels",
    "dataset_summary",
    "episode_path",
    "format_summary",
    "horizon_labels",
    "list_episode_files",
    "load_index",
    "mean_trajectory",
    "read_episode",
    "read_meta",
    "rebuild_index",
    "resample",
    "shift_trajectory",
    "verify_episode",
    "write_episode",
]
