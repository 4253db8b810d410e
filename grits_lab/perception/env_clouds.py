"""Clouds of a live ScoopEnv: reads its cameras, segmentation ids and object poses (sim API, contract 2)."""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from grits_lab.perception.clouds import pose_matrix
from grits_lab.perception.composite import CloudBuilder, CloudConfig


def as_matrix(pose: Any) -> np.ndarray:
    """(4, 4) transform from a (4, 4) matrix, a 7-D xyz + quaternion xyzw, a 9-D pose or (pos, quat)."""
    if isinstance(pose, (tuple, list)) and len(pose) == 2:
        return pose_matrix(pose[0], pose[1])
    arr = np.asarray(pose, dtype=np.float64)
    if arr.shape == (4, 4):
        return arr
    if arr.shape == (7,):
        return pose_matrix(arr[:3], arr[3:])
    if arr.shape == (9,):
        from grits_lab.geometry import rot6d_to_matrix

        m = np.eye(4)
        m[:3, :3] = rot6d_to_matrix(arr[3:])
        m[:3, 3] = arr[:3]
        return m
    raise ValueError(f"cannot read a pose of shape {arr.shape}")


def camera_list(rendered: Any, names: list[str] | None = None) -> list[dict[str, np.ndarray]]:
    """The sim's `render_cameras()` output (name -> CameraImage) as dicts in the config's camera order.

    names: keep only these cameras (None or empty: all).
    """
    items = list(rendered.items()) if isinstance(rendered, Mapping) else [(getattr(c, "name", str(i)), c) for i, c in enumerate(rendered)]
    out = []
    for name, cam in items:
        if names and name not in names:
            continue
        if isinstance(cam, Mapping):
            out.append(dict(cam))
        else:
            out.append({"rgb": cam.rgb, "depth": cam.depth, "segmentation": cam.segmentation,
                        "intrinsics": cam.intrinsics, "cam_to_world": cam.camera_to_world})
    return out


def _ids(value: Any) -> list[int]:
    return [int(v) for v in np.atleast_1d(np.asarray(value))]


def cad_meshes(spoon_geometry: Any = None, bowl_geometry: Any = None) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Spoon and source-bowl triangle meshes in their own frames, from the same shape functions that
    build the simulator's collision bodies and the meshes in assets/ (defaults: the packaged geometry)."""
    from grits_lab.sim.shapes import BowlGeometry, SpoonGeometry, bowl_boxes, boxes_to_mesh, spoon_boxes

    spoon = boxes_to_mesh(spoon_boxes(spoon_geometry or SpoonGeometry()))
    bowl = boxes_to_mesh(bowl_boxes(bowl_geometry or BowlGeometry()))
    return spoon, bowl


def builder_for_env(config: CloudConfig, env: Any) -> CloudBuilder:
    """A CloudBuilder whose CAD points come from the env's spoon and source bowl."""
    world = getattr(env, "world", None)
    spoon, bowl = cad_meshes(getattr(world, "spoon_geometry", None), getattr(world, "source_geometry", None))
    return CloudBuilder(config, spoon_mesh=spoon, bowl_mesh=bowl)


def scene_clouds(builder: CloudBuilder, env: Any, seed: int, raw: bool = False, cameras: Any = None) -> dict[str, Any]:
    """Composite cloud (and raw cloud, when asked) of the env's current state.

    Returns {"cloud": (3, N, 3), "food_points": visible food points, and with raw: "cloud_raw",
    "raw_points": visible points per object}. `cameras` reuses an existing render.
    """
    cams = camera_list(env.render_cameras() if cameras is None else cameras)
    ids = env.segmentation_ids()
    spoon, bowl = as_matrix(env.spoon_pose()), as_matrix(env.source_bowl_pose())
    food_ids = _ids(ids["food"])
    out: dict[str, Any] = {"cloud": builder.composite(cams, food_ids, spoon, bowl, seed)}
    if raw:
        body_ids = {"food": food_ids, "spoon": _ids(ids["spoon"]), "bowl": _ids(ids["source_bowl"])}
        fallbacks = {"food": bowl[:3, 3], "spoon": spoon[:3, 3], "bowl": bowl[:3, 3]}
        out["cloud_raw"], out["raw_points"] = builder.raw(cams, body_ids, fallbacks, seed)
    return out
