"""Depth + segmentation to world-frame points, per-object point sets, and farthest-point sampling to exactly N.

Camera convention (the sim's `render_cameras()`, grits_lab/sim/cameras.py): depth is metric
distance along the optical axis (z-depth, 0 or non-finite where invalid); pixel (u, v) (column,
row, 0-based) at depth z is the camera point ((u - cx) z / fx, (v - cy) z / fy, z) in OpenCV axes
(x right, y down, z forward); `cam_to_world` maps those camera axes to the world.
"""

from __future__ import annotations

import functools
from typing import Iterable, Mapping, Sequence

import numpy as np

from grits_lab.seeding import make_rng


def depth_to_points(
    depth: np.ndarray,
    intrinsics: np.ndarray,
    cam_to_world: np.ndarray,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """(H, W) depth -> (M, 3) world points of the valid pixels (and of `mask`, when given)."""
    depth = np.asarray(depth, dtype=np.float64)
    valid = np.isfinite(depth) & (depth > 0)
    if mask is not None:
        valid &= mask
    v, u = np.nonzero(valid)
    z = depth[v, u]
    k = np.asarray(intrinsics, dtype=np.float64)
    x = (u - k[0, 2]) * z / k[0, 0]
    y = (v - k[1, 2]) * z / k[1, 1]
    cam = np.stack([x, y, z], axis=1)
    return transform_points(cam, cam_to_world)


def transform_points(points: np.ndarray, transform: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) homogeneous transform to (M, 3) points."""
    t = np.asarray(transform, dtype=np.float64)
    return np.asarray(points, dtype=np.float64) @ t[:3, :3].T + t[:3, 3]


def pose_matrix(position: Sequence[float], quat_xyzw: Sequence[float]) -> np.ndarray:
    """(4, 4) transform of a pose given as position + quaternion x, y, z, w."""
    from grits_lab.geometry import quat_to_matrix

    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(np.asarray(quat_xyzw, dtype=np.float64))
    m[:3, 3] = position
    return m


def object_points(
    cameras: Iterable[Mapping[str, np.ndarray]],
    body_ids: Mapping[str, int | Sequence[int]],
    depth_key: str = "depth",
) -> dict[str, np.ndarray]:
    """Per-object world points, merged over all cameras, selected by the segmentation mask.

    cameras: dicts with `depth_key` (H, W), "segmentation" (H, W) body ids, "intrinsics" (3, 3),
    "cam_to_world" (4, 4). body_ids: object name -> one body id or a list (food particles).
    """
    cameras = list(cameras)
    out: dict[str, list[np.ndarray]] = {name: [] for name in body_ids}
    for cam in cameras:
        seg = np.asarray(cam["segmentation"])
        for name, ids in body_ids.items():
            mask = np.isin(seg, np.atleast_1d(np.asarray(ids)))
            if mask.any():
                out[name].append(depth_to_points(cam[depth_key], cam["intrinsics"], cam["cam_to_world"], mask))
    return {name: (np.concatenate(p) if p else np.zeros((0, 3))) for name, p in out.items()}


def farthest_point_sample(points: np.ndarray, n: int, seed: int = 0, fallback: Sequence[float] | None = None) -> np.ndarray:
    """Exactly `n` finite points (n, 3) float32 covering `points` (M, 3) by farthest-point sampling.

    The first point is drawn from `seed`, so the sample is reproducible. Non-finite rows are
    dropped, and exact duplicates (a cloud merged from two cameras, or voxelized, has them) count
    once. With fewer than `n` distinct points, all of them are kept and the rest are repeats drawn
    at random (a set of points, as a PointNet sees it, is unchanged by repeats). With none (object
    fully hidden), all `n` points sit at `fallback` (e.g. the object's position), or at the origin.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1)]
    if len(points):
        _, first = np.unique(points, axis=0, return_index=True)
        points = points[np.sort(first)]  # input order kept, so a cloud without repeats samples as before
    m = len(points)
    if m == 0:
        where = np.zeros(3) if fallback is None else np.asarray(fallback, dtype=np.float64)
        return np.repeat(where[None], n, axis=0).astype(np.float32)
    rng = make_rng(seed)
    if m > n:
        points = points[farthest_point_indices(points, int(n), int(rng.integers(0, m)))]
        m = len(points)
    extra = points[rng.integers(0, m, size=n - m)]
    return np.concatenate([points, extra]).astype(np.float32)


def farthest_point_indices(points: np.ndarray, n: int, start: int) -> np.ndarray:
    """Ascending indices of the `n` points of `points` (M, 3) float64 chosen by farthest-point sampling.

    From `start`, each next point is the one whose squared distance to the chosen set is largest
    (the first such index on a tie); the squared distance is summed x, y, z in that order, in
    float64. When every remaining distance is 0 (repeated points) the last choice repeats, so
    fewer than `n` indices come back. This is open3d's `PointCloud.farthest_point_down_sample`
    (open3d 0.17 to 0.20: same picks, returned in index order), written in numpy so that a plain
    install needs no open3d; with the `open3d` extra installed, open3d's C++ loop gives the same
    indices several times faster (tests/perception/test_clouds.py compares the two).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if _open3d() is not None:
        return _open3d_indices(points, n, start)
    return _numpy_indices(points, n, start)


@functools.cache
def _open3d():
    try:
        import open3d
    except ImportError:  # not installed, or its system library (libusb-1.0-0) is missing
        return None
    return open3d


def _open3d_indices(points: np.ndarray, n: int, start: int) -> np.ndarray:
    o3d = _open3d()
    tagged = np.concatenate([points, np.arange(len(points), dtype=np.float64)[:, None]], axis=1)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(np.repeat(tagged[:, 3:], 3, axis=1))  # carries each point's index
    chosen = np.asarray(cloud.farthest_point_down_sample(n, start).normals)[:, 0]
    return chosen.astype(np.int64)


def _numpy_indices(points: np.ndarray, n: int, start: int) -> np.ndarray:
    axes = [np.ascontiguousarray(points[:, k]) for k in range(3)]
    m = len(points)
    nearest = np.full(m, np.inf)  # squared distance of each point to the chosen set
    delta, squared = np.empty(m), np.empty(m)
    chosen = np.empty(n, dtype=np.int64)
    current = start
    for i in range(n):
        chosen[i] = current
        for k, axis in enumerate(axes):
            np.subtract(axis, axis[current], out=delta)
            np.multiply(delta, delta, out=delta)
            if k == 0:
                squared[:] = delta
            else:
                np.add(squared, delta, out=squared)
        np.minimum(nearest, squared, out=nearest)
        best = int(np.argmax(nearest))
        if nearest[best] > 0:
            current = best
    return np.unique(chosen)
