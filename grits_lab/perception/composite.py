"""Composite and raw point clouds of the scooping scene, (3, N, 3) in the order food, spoon, bowl.

Composite (what the predictor sees, as in GRITS): food points from depth + segmentation; spoon
points sampled once from its CAD mesh and placed at the spoon's pose from forward kinematics;
bowl points sampled once from its CAD mesh and placed at the bowl's pose. CAD points are complete
and noise-free, which is why the paper prefers them to the camera's partial view of spoon and bowl.
Raw (the ablation): every object from a noisy depth image (`noise.corrupt_depth`).
Each object is reduced to exactly `n_points` by farthest-point sampling.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

import numpy as np

from grits_lab.config import require
from grits_lab.perception.clouds import farthest_point_sample, object_points, transform_points
from grits_lab.perception.noise import DepthNoiseConfig, corrupt_depth
from grits_lab.seeding import derive_seed, make_rng

CLOUD_OBJECTS = ("food", "spoon", "bowl")  # the object order of every (3, N, 3) cloud, stored and modelled


@dataclass
class CloudConfig:
    # Points per object (the paper: 3,000). CPU presets may use fewer.
    n_points: int = 3000
    # Surface points drawn from a CAD mesh before farthest-point sampling it down to n_points.
    cad_surface_samples: int = 20000
    noise: DepthNoiseConfig = field(default_factory=DepthNoiseConfig)

    def __post_init__(self) -> None:
        require(self.n_points >= 1, "cloud.n_points", self.n_points, "at least 1")
        require(self.cad_surface_samples >= self.n_points, "cloud.cad_surface_samples", self.cad_surface_samples, "at least n_points")


def sample_mesh_surface(vertices: np.ndarray, faces: np.ndarray, n: int, seed: int) -> np.ndarray:
    """(n, 3) points uniform over a triangle mesh's surface (area-weighted triangles, uniform barycentrics)."""
    v = np.asarray(vertices, dtype=np.float64)
    tri = v[np.asarray(faces, dtype=np.int64)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if not np.isfinite(area).all() or area.sum() <= 0:
        raise ValueError("mesh has no surface area")
    rng = make_rng(seed)
    pick = rng.choice(len(tri), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    a, b, c = 1 - s, s * (1 - r2), s * r2
    t = tri[pick]
    return a[:, None] * t[:, 0] + b[:, None] * t[:, 1] + c[:, None] * t[:, 2]


class CloudBuilder:
    """Builds composite and raw clouds; holds the CAD point sets (object frame) so each step only transforms them."""

    def __init__(self, config: CloudConfig, spoon_mesh: tuple[np.ndarray, np.ndarray], bowl_mesh: tuple[np.ndarray, np.ndarray]):
        self.config = config
        n, dense = config.n_points, config.cad_surface_samples
        self.spoon_local = farthest_point_sample(sample_mesh_surface(*spoon_mesh, dense, seed=1), n, seed=1)
        self.bowl_local = farthest_point_sample(sample_mesh_surface(*bowl_mesh, dense, seed=2), n, seed=2)

    def composite(
        self,
        cameras: Iterable[Mapping[str, np.ndarray]],
        food_ids: Sequence[int],
        spoon_pose: np.ndarray,
        bowl_pose: np.ndarray,
        seed: int,
    ) -> np.ndarray:
        """(3, N, 3) float32: food from depth, spoon and bowl from CAD at their (4, 4) world poses.

        With no food pixel in view the food points sit at the bowl's origin, so the cloud stays
        finite and near the scene.
        """
        food = object_points(cameras, {"food": list(food_ids)})["food"]
        n = self.config.n_points
        return np.stack(
            [
                farthest_point_sample(food, n, seed=derive_seed(seed, "food"), fallback=np.asarray(bowl_pose)[:3, 3]),
                transform_points(self.spoon_local, spoon_pose).astype(np.float32),
                transform_points(self.bowl_local, bowl_pose).astype(np.float32),
            ]
        )

    def raw(
        self,
        cameras: Iterable[Mapping[str, np.ndarray]],
        body_ids: Mapping[str, Sequence[int]],
        fallbacks: Mapping[str, Sequence[float]],
        seed: int,
    ) -> tuple[np.ndarray, dict[str, int]]:
        """(3, N, 3) float32 with every object from noisy depth, and the visible point count per object.

        body_ids and fallbacks are keyed by CLOUD_OBJECTS names; fallback is where a fully hidden
        object's points go (its position).
        """
        rng = make_rng(derive_seed(seed, "depth-noise"))
        noisy = []
        for cam in cameras:
            cam = dict(cam)
            cam["depth"] = corrupt_depth(cam["depth"], float(cam["intrinsics"][0][0]), rng, self.config.noise)
            noisy.append(cam)
        points = object_points(noisy, {name: body_ids[name] for name in CLOUD_OBJECTS})
        n = self.config.n_points
        cloud = np.stack(
            [farthest_point_sample(points[name], n, seed=derive_seed(seed, name), fallback=fallbacks[name]) for name in CLOUD_OBJECTS]
        )
        return cloud, {name: int(len(points[name])) for name in CLOUD_OBJECTS}
