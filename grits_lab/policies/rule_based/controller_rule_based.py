"""The rule-based scoop: one open-loop motion planned from a single look at the food.

Spoon frame (contract 1): x towards the tip, z along the bowl's normal (the food side). With the
identity rotation the spoon lies level, tip pointing away from the robot (+x). A positive pitch
about the world y axis tips the tip down. The motion (SPEC, Baselines): go above the bowl
centre, measure the food's surface height from the RGB-D food points, rotate to the entry pose,
dig to a fixed depth of 5 cm below the surface (never below the bowl floor), then a fixed
stroke that drags the spoon forwards while levelling it, and lift.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from grits_lab.geometry import matrix_to_rot6d


def pitch_pose(position: np.ndarray, pitch_rad: float) -> np.ndarray:
    """(9,) spoon pose at `position` with the tip pitched down by `pitch_rad` about world y."""
    c, s = math.cos(pitch_rad), math.sin(pitch_rad)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return np.concatenate([np.asarray(position, dtype=np.float64), matrix_to_rot6d(rot)]).astype(np.float32)


def food_surface_height(points: np.ndarray, centre: np.ndarray, radius: float, fallback: float) -> float:
    """Height of the food's top surface near `centre`: the 90th percentile z of the visible food
    points within `radius` (xy) of it; the top layer is what the cameras see."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    near = pts[np.linalg.norm(pts[:, :2] - np.asarray(centre)[:2], axis=1) < radius]
    if len(near) < 5:
        near = pts
    return float(np.percentile(near[:, 2], 90)) if len(near) else float(fallback)


def _segment(start: np.ndarray, end: np.ndarray, steps: int) -> list[np.ndarray]:
    """Waypoints from `start` (excluded) to `end` (included), positions and 6-D rotations interpolated."""
    from grits_lab.data.trajectories import resample

    return list(resample(np.stack([start, end]), steps + 1)[1:].astype(np.float32))


class RuleBasedController:
    """Plans the whole scoop at the first call from the food height it measures; then done."""

    cloud_steps = 0
    image_steps = 0

    def __init__(self, settings: Any) -> None:
        self.settings = settings
        self.done = False
        self.measured: dict[str, float] = {}

    def reset(self, scene: Any) -> None:
        self.done = False
        self.measured = {}

    def plan(self, history: Any, scene: Any) -> Chunk | None:
        from grits_lab.policies.control import Chunk

        if self.done:
            return None
        s = self.settings
        bowl = scene.source_bowl_position()
        geometry = scene.source_geometry()
        floor = bowl[2] + geometry.floor_thickness
        rim = bowl[2] + geometry.depth
        surface = food_surface_height(scene.food_points(), bowl, geometry.floor_radius, fallback=floor + 0.01)
        pitch = math.radians(s.entry_pitch_deg)
        spoon = scene.spoon_geometry()
        # Dig: the spoon's centre goes 5 cm below the surface, but its tip (lower by half a spoon
        # length times sin(pitch)) stays a few millimetres above the floor.
        floor_clear = lambda p: floor + spoon.half_length * math.sin(max(p, 0.0)) + 0.004
        dig_z = max(surface - s.dig_depth, floor_clear(pitch))
        stroke_pitch = math.radians(10.0)
        stroke_z = max(surface - s.dig_depth, floor_clear(stroke_pitch))
        start_xy = bowl[:2] - np.array([s.drag / 2, 0.0])
        end_xy = bowl[:2] + np.array([s.drag / 2, 0.0])
        current = history.ee_pose[-1].astype(np.float64)
        above = pitch_pose(np.array([start_xy[0], start_xy[1], rim + 0.06]), 0.0)
        entry_above = pitch_pose(np.array([start_xy[0], start_xy[1], rim + 0.03]), pitch)
        dig = pitch_pose(np.array([start_xy[0], start_xy[1], dig_z]), pitch)
        stroke = pitch_pose(np.array([end_xy[0] - 0.012, end_xy[1], stroke_z]), stroke_pitch)
        tilt = pitch_pose(np.array([end_xy[0], end_xy[1], stroke_z + 0.006]), math.radians(-12.0))
        lift = pitch_pose(np.array([end_xy[0] - 0.01, end_xy[1], rim + s.lift_height]), math.radians(-12.0))
        n = s.steps_per_segment
        waypoints = (_segment(current, above, n) + _segment(above, entry_above, n) + _segment(entry_above, dig, n)
                     + _segment(dig, stroke, 2 * n) + _segment(stroke, tilt, n) + _segment(tilt, lift, 2 * n))
        self.done = True
        self.measured = {"surface_height": surface, "dig_z": dig_z}
        return Chunk(np.stack(waypoints), {"surface_height": surface})
