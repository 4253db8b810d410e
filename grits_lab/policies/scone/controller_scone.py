"""SCONE-style scooping: a vertical probe measures the food, and the measurements condition the scoop.

SCONE learns what a scoop should be from an interaction that reveals the food's properties. Here
the interaction is a probe: the spoon, tip down, is lowered into the centre of the bowl a few
millimetres per action while the force between spoon and food is read (a wrist force sensor's
reading); the first step above `contact_force` gives the food's surface height, and the force
gathered over the following `probe_depth` gives its resistance (N per cm of penetration). The
scoop is the mean demonstration (the learned motion prior), shifted so that its deepest point
sits at the measured surface minus a depth that shrinks for resistant food (stiff or sticky
food jams a deep scoop) and grows for loose food, clamped to the bowl's floor.
Nothing in it models spillage, which is the paper's point about this baseline.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from grits_lab.policies.rule_based.controller_rule_based import pitch_pose


def scoop_prior(demos_dir: str | Path) -> np.ndarray:
    """(T, 9) mean commanded trajectory of the demonstrations (time-normalized; grits_lab.data.trajectories)."""
    from grits_lab.data.format import read_episode
    from grits_lab.data.trajectories import mean_trajectory
    from grits_lab.policies.diffusion.demo_windows import list_demo_episodes

    ids = list_demo_episodes(demos_dir)
    actions = [read_episode(Path(demos_dir) / "episodes" / f"{e}.npz", keys=["action"])[0]["action"] for e in ids]
    return mean_trajectory(actions).astype(np.float32)


@dataclass
class ProbeResult:
    surface_height: float  # world z of the food surface (tip height at first contact)
    resistance: float  # N per cm of penetration below the surface
    depth_scale: float  # how the scoop's depth was scaled


def adapt_scoop(prior: np.ndarray, surface: float, floor: float, depth: float, tip_drop: float) -> np.ndarray:
    """Shift the prior vertically so its deepest waypoint lies `depth` below `surface`, but no closer
    to the floor than `tip_drop` (the tip hangs below the spoon's centre when pitched)."""
    out = prior.copy()
    low = int(np.argmin(prior[:, 2]))
    target = max(surface - depth, floor + tip_drop)
    dz = target - float(prior[low, 2])
    # Shift the part of the scoop inside the bowl fully, and fade the shift out towards the start
    # and the end so the approach and the lift keep their heights.
    weight = np.ones(len(prior))
    above = prior[:, 2] > floor + 0.08
    weight[above] = 0.0
    out[:, 2] += dz * weight.astype(np.float32)
    return out


class SconeController:
    """Probe (one action per plan, reading the force after each), then the conditioned scoop in one chunk."""

    cloud_steps = 0
    image_steps = 0

    def __init__(self, settings: Any, prior: np.ndarray) -> None:
        self.settings = settings
        self.prior = np.asarray(prior, dtype=np.float32)
        self.reset(None)

    def reset(self, scene: Any) -> None:
        self.phase = "approach"
        self.contact_z: float | None = None
        self.forces: list[tuple[float, float]] = []  # (tip z, force)
        self.probe: ProbeResult | None = None
        self.z = 0.0

    def _tip_pose(self, scene: Any, z: float) -> np.ndarray:
        bowl = scene.source_bowl_position()
        # Tip down at 40 degrees (steeper poses leave the arm's reach); the centre sits above the tip.
        half = scene.spoon_geometry().half_length
        pitch = math.radians(40.0)
        return pitch_pose(np.array([bowl[0], bowl[1], z + half * math.sin(pitch)]), pitch)

    def plan(self, history: Any, scene: Any) -> Chunk | None:
        from grits_lab.policies.control import Chunk

        s = self.settings
        geometry = scene.source_geometry()
        bowl = scene.source_bowl_position()
        floor, rim = bowl[2] + geometry.floor_thickness, bowl[2] + geometry.depth
        if self.phase == "approach":
            self.phase, self.z = "probe", rim + 0.01
            current = history.ee_pose[-1].astype(np.float64)
            target = self._tip_pose(scene, self.z)
            steps = 12
            path = [current + (target - current) * (i / steps) for i in range(1, steps + 1)]
            return Chunk(np.stack(path).astype(np.float32), {"phase": "approach"})
        if self.phase == "probe":
            force = scene.spoon_contact_force()
            self.forces.append((self.z, force))
            if self.contact_z is None and force > s.contact_force:
                self.contact_z = self.z
            reached_floor = self.z <= floor + 0.004
            if (self.contact_z is not None and self.z <= self.contact_z - s.probe_depth) or reached_floor:
                self._finish_probe(floor)
                self.phase = "scoop"
                up = self._tip_pose(scene, rim + 0.04)
                current = history.ee_pose[-1].astype(np.float64)
                path = [current + (up - current) * (i / 6) for i in range(1, 7)]
                return Chunk(np.stack(path).astype(np.float32), {"phase": "retreat"})
            self.z -= s.probe_step
            return Chunk(self._tip_pose(scene, self.z)[None], {"phase": "probe"})
        if self.phase == "scoop":
            self.phase = "done"
            assert self.probe is not None
            depth = 0.03 * self.probe.depth_scale
            spoon = scene.spoon_geometry()
            scoop = adapt_scoop(self.prior, self.probe.surface_height, floor, depth, spoon.half_length * 0.5 + 0.004)
            current = history.ee_pose[-1].astype(np.float64)
            lead = [current + (scoop[0] - current) * (i / 8) for i in range(1, 9)]
            return Chunk(np.concatenate([np.stack(lead).astype(np.float32), scoop]), {"phase": "scoop"})
        return None

    def _finish_probe(self, floor: float) -> None:
        s = self.settings
        surface = self.contact_z if self.contact_z is not None else floor
        below = [(surface - z, f) for z, f in self.forces if z < surface]
        if below:
            depth_cm = max(d for d, _ in below) * 100
            resistance = float(np.mean([f for _, f in below])) / max(depth_cm, 0.1)
        else:
            resistance = 0.0
        scale = s.reference_resistance / resistance if resistance > 0 else s.max_depth_scale
        self.probe = ProbeResult(float(surface), resistance, float(np.clip(scale, s.min_depth_scale, s.max_depth_scale)))
