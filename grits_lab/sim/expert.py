"""The scripted expert scoop: keyframes relative to the source bowl, interpolated to 10 Hz actions.

The motion is what a person does with a ladle: hover over the near half of the bowl with the
tip down, dig in near the floor, drag through the food towards the far wall while levelling the
spoon, tip it slightly up so the load rests in the spoon, and lift straight out. The nominal
(unrandomized) trajectory depends only on the scene geometry, which makes it the "mean
demonstration" the spillage dataset shifts; `expert_trajectory` perturbs it per seed (entry
point, depth, angles, heading and speed within a few millimetres / degrees / percent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grits_lab.sim.env import SceneGeometry, interpolate_pose, matrix_to_pose9, pose9_to_matrix


@dataclass(frozen=True)
class Keyframe:
    time_s: float
    offset: tuple[float, float, float]  # (forward, left, up): forward from the bowl centre, up from the floor or rim
    pitch_deg: float  # tip down positive
    above_rim: bool = False  # `up` measured from the rim instead of the inner floor


# Forward is +x of the world (away from the robot); the scoop runs from the near to the far side.
KEYFRAMES = (
    Keyframe(1.5, (-0.026, 0.0, 0.05), 35.0, above_rim=True),
    Keyframe(2.5, (-0.026, 0.0, 0.016), 25.0),
    Keyframe(3.6, (-0.008, 0.0, 0.007), 14.0),
    Keyframe(4.4, (0.010, 0.0, 0.004), 4.0),
    Keyframe(5.1, (0.012, 0.0, 0.011), -14.0),
    Keyframe(6.3, (0.006, 0.0, 0.06), -14.0, above_rim=True),
    Keyframe(6.7, (0.006, 0.0, 0.06), -14.0, above_rim=True),
)


def spoon_orientation(pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """(3, 3) spoon rotation: heading `yaw` about world z, then `pitch` (tip down positive) about spoon y."""
    p, y = math.radians(pitch_deg), math.radians(yaw_deg)
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    return rz @ ry


def _keyframe_poses(scene: SceneGeometry, shift: np.ndarray, depth: float, pitch: float, yaw_deg: float,
                    keyframes: tuple[Keyframe, ...]) -> list[np.ndarray]:
    centre = np.array(scene.source_bowl_center)
    floor_z = scene.source_bowl_floor_height
    rim_z = scene.source_bowl_rim_height
    yaw = math.radians(yaw_deg)
    heading = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    poses = []
    for k in keyframes:
        fwd, left, up = k.offset
        xy = centre[:2] + heading @ np.array([fwd, left]) + shift[:2]
        z = centre[2] + (rim_z if k.above_rim else floor_z) + up + (0.0 if k.above_rim else depth)
        m = np.eye(4)
        m[:3, 3] = [xy[0], xy[1], z]
        m[:3, :3] = spoon_orientation(k.pitch_deg + pitch, yaw_deg)
        poses.append(m)
    return poses


def _sample(start: np.ndarray, poses: list[np.ndarray], times: list[float], hz: float) -> np.ndarray:
    """Piecewise pose interpolation from `start` (t = 0) through keyframes, sampled at `hz` after t = 0."""
    frames = [start] + poses
    ts = [0.0] + times
    out = []
    n = int(round(ts[-1] * hz))
    for i in range(1, n + 1):
        t = i / hz
        j = min(np.searchsorted(ts, t, side="left"), len(ts) - 1)
        j = max(j, 1)
        u = (t - ts[j - 1]) / (ts[j] - ts[j - 1])
        u = 0.5 - 0.5 * math.cos(math.pi * min(max(u, 0.0), 1.0))  # ease in and out of each keyframe
        out.append(matrix_to_pose9(interpolate_pose(frames[j - 1], frames[j], u)))
    return np.array(out, dtype=np.float32)


def nominal_expert_trajectory(scene: SceneGeometry, control_hz: float = 10.0) -> np.ndarray:
    """(T, 9) the unrandomized expert scoop for this scene, starting from the spoon's home pose."""
    poses = _keyframe_poses(scene, np.zeros(3), 0.0, 0.0, 0.0, KEYFRAMES)
    return _sample(pose9_to_matrix(np.array(scene.spoon_home)), poses, [k.time_s for k in KEYFRAMES], control_hz)


def expert_trajectory(scene: SceneGeometry, rng: np.random.Generator, control_hz: float = 10.0) -> np.ndarray:
    """(T, 9) a randomized expert scoop: the nominal one with a shifted entry, depth, angles, heading and pace."""
    shift = np.array([rng.uniform(-0.006, 0.006), rng.uniform(-0.012, 0.012), 0.0])
    depth = rng.uniform(-0.003, 0.003)
    pitch = rng.uniform(-4.0, 4.0)
    yaw = rng.uniform(-12.0, 12.0)
    pace = rng.uniform(0.9, 1.15)
    poses = _keyframe_poses(scene, shift, depth, pitch, yaw, KEYFRAMES)
    times = [k.time_s * pace for k in KEYFRAMES]
    return _sample(pose9_to_matrix(np.array(scene.spoon_home)), poses, times, control_hz)
