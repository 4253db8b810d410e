"""What a controller may perceive during an episode: cameras, clouds, food points, bowl poses and the spoon's contact force.

`EpisodeScene` wraps a live ScoopEnv for one episode. Renders and clouds are cached per step
(a render costs tens of milliseconds per camera), so a controller and the guidance objective
that both ask for the current cloud pay for one render. Nothing here changes the simulation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from grits_lab.perception.clouds import object_points
from grits_lab.perception.composite import CloudBuilder
from grits_lab.perception.env_clouds import camera_list, scene_clouds
from grits_lab.seeding import derive_seed

if TYPE_CHECKING:  # annotations only
    from grits_lab.sim.cameras import CameraImage
    from grits_lab.sim.shapes import BowlGeometry, SpoonGeometry


def camera_dicts(rendered: dict[str, CameraImage]) -> list[dict[str, np.ndarray]]:
    """The env's CameraImage objects as the dicts perception reads (stable camera order)."""
    out = []
    for cam in camera_list(rendered):
        if isinstance(cam, dict):
            out.append(cam)
            continue
        out.append({"rgb": cam.rgb, "depth": cam.depth, "segmentation": cam.segmentation,
                    "intrinsics": cam.intrinsics, "cam_to_world": cam.camera_to_world, "name": cam.name})
    return out


class EpisodeScene:
    """Read-only access to one episode's sensors; `step` is the number of actions executed so far."""

    def __init__(self, env: Any, builder: CloudBuilder, seed: int) -> None:
        self.env = env
        self.builder = builder
        self.seed = int(seed)
        self.step = 0
        self._cache: dict[tuple[str, int], Any] = {}
        self.renders = 0

    def advance(self) -> None:
        self.step += 1
        self._cache = {k: v for k, v in self._cache.items() if k[1] == self.step}

    def _cached(self, name: str, factory: Any) -> Any:
        key = (name, self.step)
        if key not in self._cache:
            self._cache[key] = factory()
        return self._cache[key]

    # ---- cameras and clouds --------------------------------------------------------------
    def cameras(self) -> list[dict[str, np.ndarray]]:
        def render() -> list[dict[str, np.ndarray]]:
            self.renders += 1
            return camera_dicts(self.env.render_cameras())

        return self._cached("cameras", render)

    def _clouds(self, raw: bool) -> dict[str, Any]:
        seed = derive_seed(self.seed, "cloud", self.step)
        return scene_clouds(self.builder, self.env, seed, raw=raw, cameras=self.cameras())

    def cloud(self) -> np.ndarray:
        """(3, N, 3) composite cloud (food from depth + segmentation, spoon and bowl from CAD) now."""
        return self._cached("cloud", lambda: self._clouds(False)["cloud"])

    def cloud_raw(self) -> np.ndarray:
        """(3, N, 3) every object from noisy depth (the raw-cloud ablation's input) now."""
        return self._cached("cloud_raw", lambda: self._clouds(True)["cloud_raw"])

    def object_points(self, name: str) -> np.ndarray:
        """(M, 3) world points of the named bodies (segmentation_ids key) seen by the cameras now."""
        ids = self.env.segmentation_ids()[name]
        return self._cached(f"points:{name}", lambda: object_points(self.cameras(), {name: ids})[name])

    def food_points(self) -> np.ndarray:
        return self.object_points("food")

    def rgbd(self, size: tuple[int, int], cameras: int) -> np.ndarray:
        """(cams, 4, H, W) float32: RGB in [0, 255] and depth in metres, resized (nearest) to `size`."""
        def build() -> np.ndarray:
            out = []
            for cam in self.cameras()[:cameras]:
                h, w = cam["depth"].shape
                rows = (np.arange(size[0]) * h / size[0]).astype(int)
                cols = (np.arange(size[1]) * w / size[1]).astype(int)
                rgb = cam["rgb"][rows][:, cols].astype(np.float32).transpose(2, 0, 1)
                depth = cam["depth"][rows][:, cols].astype(np.float32)[None]
                out.append(np.concatenate([rgb, depth]))
            return np.stack(out)

        return self._cached(f"rgbd:{size}:{cameras}", build)

    # ---- geometry and proprioception ----------------------------------------------------
    def source_bowl_position(self) -> np.ndarray:
        return np.asarray(self.env.source_bowl_pose(), dtype=np.float64)[:3, 3].copy()

    def source_geometry(self) -> BowlGeometry:
        return self.env.world.source_geometry

    def spoon_geometry(self) -> SpoonGeometry:
        return self.env.world.spoon_geometry

    def spoon_pose(self) -> np.ndarray:
        return np.asarray(self.env.spoon_pose(), dtype=np.float64)

    def spoon_contact_force(self) -> float:
        """Newtons: total normal force between the spoon and the food now (a wrist force sensor's reading
        minus gravity; the probe of SCONE reads it)."""
        world = self.env.world
        food = set(int(b) for b in world.particles)
        total = 0.0
        for contact in world.client.getContactPoints(bodyA=world.spoon):
            if int(contact[2]) in food:
                total += float(contact[9])
        return total
