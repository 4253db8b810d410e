"""Trajectory helpers for the spillage dataset: the mean of expert trajectories and feasible random shifts."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from grits_lab.geometry import matrix_to_rot6d, pose7_to_pose9, rot6d_to_matrix


def as_pose9(traj: np.ndarray) -> np.ndarray:
    """(T, 9) or (T, 7) xyz + quaternion xyzw -> (T, 9) float64."""
    traj = np.asarray(traj, dtype=np.float64)
    if traj.ndim != 2 or traj.shape[1] not in (7, 9):
        raise ValueError(f"a trajectory must be (T, 9) or (T, 7); got {traj.shape}")
    return pose7_to_pose9(traj) if traj.shape[1] == 7 else traj


def resample(traj: np.ndarray, length: int) -> np.ndarray:
    """Linear resampling of a (T, 9) trajectory to `length` waypoints (rotation re-orthonormalized)."""
    traj = as_pose9(traj)
    src = np.linspace(0.0, 1.0, len(traj))
    dst = np.linspace(0.0, 1.0, length)
    out = np.stack([np.interp(dst, src, traj[:, d]) for d in range(9)], axis=1)
    out[:, 3:] = matrix_to_rot6d(rot6d_to_matrix(out[:, 3:]))
    return out


def mean_trajectory(trajectories: Sequence[np.ndarray], length: int | None = None) -> np.ndarray:
    """Time-normalized mean of trajectories of different lengths: (length, 9), median length by default.

    Positions are averaged; rotations are averaged in 6-D and projected back onto rotations by
    Gram-Schmidt, which is accurate for the nearby orientations of one expert.
    """
    if not trajectories:
        raise ValueError("no trajectories to average")
    length = length or int(np.median([len(t) for t in trajectories]))
    mean = np.mean([resample(t, length) for t in trajectories], axis=0)
    mean[:, 3:] = matrix_to_rot6d(rot6d_to_matrix(mean[:, 3:]))
    return mean


def shift_trajectory(
    base: np.ndarray,
    shift: np.ndarray,
    bowl_center: np.ndarray,
    inner_radius_at,
    rim_height: float,
    floor_height: float,
    clearance: float = 0.02,
    ramp_steps: int = 5,
) -> tuple[np.ndarray, float]:
    """Shift a trajectory's positions by `shift` (3,), scaled down as little as needed to stay feasible.

    The shift ramps in over the first `ramp_steps` waypoints (the spoon starts from its home pose).
    Feasible: every waypoint below the rim stays `clearance` inside the bowl's inner wall and above
    its floor, or no further out than the base trajectory itself goes. Returns the trajectory and
    the scale applied to the shift (1.0 = unchanged).
    """
    base = as_pose9(base)
    ramp = np.minimum(1.0, (np.arange(len(base)) + 1) / max(1, ramp_steps))[:, None]
    center = np.asarray(bowl_center, dtype=np.float64)

    def violation(traj: np.ndarray) -> np.ndarray:
        """(T, 2): how far each waypoint is outside the wall margin and below the floor margin (<= 0: fine)."""
        rel = traj[:, :3] - center
        inside = (rel[:, 2] < rim_height)[:, None]
        radial = np.linalg.norm(rel[:, :2], axis=1) - (inner_radius_at(rel[:, 2]) - clearance)
        below = (floor_height + 0.005) - rel[:, 2]
        return np.where(inside, np.stack([radial, below], axis=1), -np.inf)

    allowed = np.maximum(violation(base), 0.0) + 1e-9  # per waypoint and per constraint

    def shifted(scale: float) -> np.ndarray:
        out = base.copy()
        out[:, :3] += scale * ramp * np.asarray(shift, dtype=np.float64)
        return out

    if np.all(violation(shifted(1.0)) <= allowed):
        return shifted(1.0), 1.0
    lo, hi = 0.0, 1.0
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        if np.all(violation(shifted(mid)) <= allowed):
            lo = mid
        else:
            hi = mid
    return shifted(lo), lo
