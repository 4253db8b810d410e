"""Rotation conversions for the 9-D action (xyz + 6-D rotation) used by every policy and dataset.

The 6-D rotation is the first two columns of the rotation matrix, stacked column by column:
[R00, R10, R20, R01, R11, R21] (Zhou et al., 2019). It is continuous, unlike quaternions or
Euler angles, which is why diffusion policies regress it.
"""

from __future__ import annotations

import math

import numpy as np


def quat_to_matrix(quat_xyzw: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions x, y, z, w -> (..., 3, 3) rotation matrices."""
    q = np.asarray(quat_xyzw, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - z * w)
    m[..., 0, 2] = 2 * (x * z + y * w)
    m[..., 1, 0] = 2 * (x * y + z * w)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - x * w)
    m[..., 2, 0] = 2 * (x * z - y * w)
    m[..., 2, 1] = 2 * (y * z + x * w)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def matrix_to_quat(matrix: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) quaternions x, y, z, w with w >= 0."""
    m = np.asarray(matrix, dtype=np.float64)
    flat = m.reshape(-1, 3, 3)
    out = np.empty((flat.shape[0], 4))
    for i, r in enumerate(flat):
        trace = r[0, 0] + r[1, 1] + r[2, 2]
        if trace > 0:
            s = np.sqrt(trace + 1.0) * 2
            out[i] = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
        elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
            s = np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
            out[i] = [0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
        elif r[1, 1] > r[2, 2]:
            s = np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
            out[i] = [(r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
        else:
            s = np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
            out[i] = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s, (r[1, 0] - r[0, 1]) / s]
    out[out[:, 3] < 0] *= -1
    out /= np.linalg.norm(out, axis=-1, keepdims=True)
    return out.reshape(m.shape[:-2] + (4,))


def matrix_to_rot6d(matrix: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 6): the first two columns, column by column."""
    m = np.asarray(matrix, dtype=np.float64)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def rot6d_to_matrix(rot6d: np.ndarray) -> np.ndarray:
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt, so any 6-vector (e.g. a noisy sample) maps to a rotation."""
    r = np.asarray(rot6d, dtype=np.float64)
    a1, a2 = r[..., 0:3], r[..., 3:6]
    b1 = a1 / np.clip(np.linalg.norm(a1, axis=-1, keepdims=True), 1e-9, None)
    a2 = a2 - np.sum(b1 * a2, axis=-1, keepdims=True) * b1
    b2 = a2 / np.clip(np.linalg.norm(a2, axis=-1, keepdims=True), 1e-9, None)
    b3 = np.cross(b1, b2)
    return np.stack([b1, b2, b3], axis=-1)


def quat_to_rot6d(quat_xyzw: np.ndarray) -> np.ndarray:
    return matrix_to_rot6d(quat_to_matrix(quat_xyzw))


def rot6d_to_quat(rot6d: np.ndarray) -> np.ndarray:
    return matrix_to_quat(rot6d_to_matrix(rot6d))


def pose7_to_pose9(pose7: np.ndarray) -> np.ndarray:
    """(..., 7) xyz + quaternion xyzw -> (..., 9) xyz + 6-D rotation."""
    p = np.asarray(pose7, dtype=np.float64)
    return np.concatenate([p[..., :3], quat_to_rot6d(p[..., 3:7])], axis=-1)


def pose9_to_pose7(pose9: np.ndarray) -> np.ndarray:
    """(..., 9) xyz + 6-D rotation -> (..., 7) xyz + quaternion xyzw."""
    p = np.asarray(pose9, dtype=np.float64)
    return np.concatenate([p[..., :3], rot6d_to_quat(p[..., 3:9])], axis=-1)


def rotation_vector(matrix: np.ndarray) -> np.ndarray:
    """(3,) axis-angle vector (unit axis times the angle in [0, pi], radians) of a (3, 3) rotation:
    the inverse of `axis_angle_matrix`, through the quaternion, so it stays exact near 0 and pi."""
    x, y, z, w = matrix_to_quat(np.asarray(matrix, dtype=np.float64))
    v = np.array([x, y, z]) * (1.0 if w >= 0 else -1.0)
    s = float(np.linalg.norm(v))
    if s < 1e-12:
        return np.zeros(3)
    return v / s * 2.0 * math.atan2(s, abs(w))


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3,) axis-angle vector (radians) of the shortest rotation taking direction `a` (3,) to `b` (3,):
    its axis is a x b, so it has no component along either; zero when they agree, and for
    opposite directions any axis normal to `a`."""
    a = np.asarray(a, dtype=np.float64) / np.linalg.norm(a)
    b = np.asarray(b, dtype=np.float64) / np.linalg.norm(b)
    axis = np.cross(a, b)
    s, c = float(np.linalg.norm(axis)), float(np.clip(a @ b, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.zeros(3)
        normal = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return normal / np.linalg.norm(normal) * math.pi
    return axis / s * math.atan2(s, c)


def skew(v: np.ndarray) -> np.ndarray:
    """(3, 3) the cross-product matrix of `v` (3,): skew(v) @ u == np.cross(v, u)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def axis_angle_matrix(axis: np.ndarray, angles: np.ndarray | float) -> np.ndarray:
    """(..., 3, 3) rotations by `angles` (radians) about one unit `axis` (3,), by Rodrigues' formula."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    a = np.asarray(angles, dtype=np.float64)[..., None, None]
    K = skew(k)
    return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * (K @ K)


def cubic_pose_path(start: np.ndarray, waypoints: np.ndarray, pieces: int) -> np.ndarray:
    """(T, pieces, 9) poses a C1 cubic spline passes through between 9-D waypoints, `pieces` per span.

    start: (9,) the pose before the first waypoint; waypoints: (T, 9), one per control period.
    Span t runs from waypoint t-1 (start for t = 0) to waypoint t; its entries are the spline at
    (j + 1) / pieces of the span, so entry [t, -1] is waypoint t. The spline is a cubic Hermite
    curve per span in position and in the 6-D rotation (re-orthonormalised by `rot6d_to_matrix`),
    with Catmull-Rom tangents (the central difference of the neighbouring waypoints) and zero
    velocity at the first and last waypoint: velocity is continuous across the waypoints, where
    straight spans between them step it at every one. This is the cubic interpolation a robot's
    trajectory controller applies between via points that carry velocities (ROS
    joint_trajectory_controller; Catmull & Rom 1974). ValueError for other shapes or pieces < 1.
    """
    first, rest = np.asarray(start, dtype=np.float64), np.asarray(waypoints, dtype=np.float64)
    if first.shape != (9,) or rest.ndim != 2 or rest.shape[1] != 9 or pieces < 1:
        raise ValueError(f"need start (9,), waypoints (T, 9) and pieces >= 1; got {first.shape}, {rest.shape} and {pieces}")
    p = np.concatenate([first[None], rest])
    tangents = np.zeros_like(p)
    tangents[1:-1] = (p[2:] - p[:-2]) / 2.0
    s = (np.arange(1, pieces + 1) / pieces)[None, :, None]
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
    out = h00 * p[:-1, None] + h10 * tangents[:-1, None] + h01 * p[1:, None] + h11 * tangents[1:, None]
    out[..., 3:9] = matrix_to_rot6d(rot6d_to_matrix(out[..., 3:9]))
    return out
