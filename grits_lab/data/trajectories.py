"""Trajectory helpers for the spillage dataset: the mean of expert trajectories and feasible random shifts."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from grits_lab.geometry import axis_angle_matrix, matrix_to_rot6d, pose7_to_pose9, rot6d_to_matrix


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


def _ease(n: int) -> np.ndarray:
    """Progress 0 -> 1 over `n` steps (values after each step), cosine-eased in and out."""
    return 0.5 - 0.5 * np.cos(np.pi * np.arange(1, n + 1) / n)


def append_exit(
    base: np.ndarray,
    bowl_center: np.ndarray,
    direction_xy: np.ndarray,
    distance: float,
    rise: float,
    speed: float,
    hold_steps: int,
    control_hz: float,
    tilt: float = 0.0,
    tilt_steps: int = 0,
) -> np.ndarray:
    """The base scoop followed by the lift-and-exit: (T + n_exit + tilt_steps + hold_steps, 9).

    From the scoop's last pose the spoon travels horizontally along `direction_xy` until its centre
    is `distance` from the bowl's axis, rising by `rise`, at an average `speed` (m/s, eased in and
    out like the expert's keyframes), keeping the scoop's orientation; there, outside the bowl, it
    rolls by `tilt` radians about the direction of travel over `tilt_steps` actions (eased), and
    then holds still for `hold_steps` actions so that food sliding off the spoon lands before the
    trial ends. Food that falls off past the rim lands on the table: the spillage a real
    scoop-and-transfer causes when the spoon is overloaded, jerked or tipped. The roll happens
    outside the bowl so that what it sheds counts (a roll over the bowl would return food to it);
    it is what makes the upcoming motion, not only the state at a chunk's start, decide a label.
    """
    base = as_pose9(base)
    d = np.asarray(direction_xy, dtype=np.float64)
    d = d / np.linalg.norm(d)
    last = base[-1]
    rel = last[:2] - np.asarray(bowl_center, dtype=np.float64)[:2]
    # Distance to travel along d so that |rel + s d| = distance (the positive root).
    b = float(rel @ d)
    s_end = -b + float(np.sqrt(max(b * b - (rel @ rel - distance**2), 0.0)))
    n = max(1, int(np.ceil(s_end / speed * control_hz)))
    u = _ease(n)
    exit_ = np.repeat(last[None], n + tilt_steps + hold_steps, axis=0)
    exit_[:n, :2] = last[:2] + np.outer(u * s_end, d)
    exit_[:n, 2] = last[2] + u * rise
    exit_[n:, :3] = exit_[n - 1, :3]
    if tilt and tilt_steps:
        angles = np.concatenate([np.zeros(n), _ease(tilt_steps), np.ones(hold_steps)]) * tilt
        axis = np.array([d[0], d[1], 0.0])
        exit_[:, 3:9] = matrix_to_rot6d(axis_angle_matrix(axis, angles) @ rot6d_to_matrix(last[3:9]))
    return np.concatenate([base, exit_], axis=0)


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
    """Shift a trajectory's positions by `shift` (3,), each waypoint projected back into the feasible region.

    The shift ramps in over the first `ramp_steps` waypoints (the spoon starts from its home pose).
    Feasible: below the rim, and above it where the base lies over the bowl (inside its rim
    circle), the spoon's centre stays `clearance` inside the bowl's inner wall at its height (the
    rim's radius above the rim); below the rim it also stays 5 mm above the floor. Where the base
    itself is further out or lower, the base's own excess is allowed. An infeasible waypoint is
    moved the least: up to the floor margin, then radially in to the wall margin, so the rest of
    the shift survives (a shift into the far wall drags the spoon along it, as a person scraping
    the side would). Waypoints above the rim with the base outside the rim circle (the approach
    from home, the exit towards the transfer) keep the full shift. Returns the trajectory and the mean fraction of the shift kept
    over the shifted waypoints (1.0 = applied in full).
    """
    base = as_pose9(base)
    shift = np.asarray(shift, dtype=np.float64)
    ramp = np.minimum(1.0, (np.arange(len(base)) + 1) / max(1, ramp_steps))[:, None]
    center = np.asarray(bowl_center, dtype=np.float64)
    rim_radius = float(inner_radius_at(rim_height))
    base_rel = base[:, :3] - center
    base_r = np.linalg.norm(base_rel[:, :2], axis=1)
    over_bowl = base_r < rim_radius

    def wall_margin(z: np.ndarray) -> np.ndarray:
        return inner_radius_at(np.minimum(z, rim_height)) - clearance

    floor_margin = floor_height + 0.005
    # The base's own excess over each margin is allowed (its waypoints are feasible by definition).
    floor_allowed = np.where(base_rel[:, 2] < rim_height, np.minimum(floor_margin, base_rel[:, 2]), -np.inf)
    wall_excess = np.maximum(base_r - wall_margin(base_rel[:, 2]), 0.0)

    rel = base_rel + ramp * shift
    # Floor first (a lower waypoint is moved up), then the wall at the resulting height.
    below_rim = rel[:, 2] < rim_height
    rel[:, 2] = np.where(below_rim, np.maximum(rel[:, 2], floor_allowed), rel[:, 2])
    r = np.linalg.norm(rel[:, :2], axis=1)
    r_max = wall_margin(rel[:, 2]) + wall_excess
    too_far = (over_bowl | (rel[:, 2] < rim_height)) & (r > r_max)
    factor = np.where(too_far, r_max / np.maximum(r, 1e-12), 1.0)
    rel[:, :2] *= factor[:, None]
    out = base.copy()
    out[:, :3] = rel + center
    wanted = np.linalg.norm(ramp * shift, axis=1)
    kept = np.linalg.norm(out[:, :3] - base[:, :3], axis=1)
    moved = wanted > 1e-12
    scale = float(np.mean(np.minimum(kept[moved] / wanted[moved], 1.0))) if moved.any() else 1.0
    return out, scale
