"""Fixed RGB-D cameras with segmentation: images, metric depth, intrinsics and camera-to-world poses.

Conventions (what the perception code relies on):
- `intrinsics` K is the usual pinhole matrix; pixel (u, v) (column, row, 0-based) at depth z
  back-projects to camera coordinates ((u - cx) z / fx, (v - cy) z / fy, z).
- `camera_to_world` (4, 4) maps those camera coordinates (OpenCV axes: x right, y down, z
  forward) to the world frame.
- `depth` is metric distance along the optical axis (float32 metres); `segmentation` holds the
  PyBullet body id of each pixel (-1 for background); `ScoopEnv.segmentation_ids()` names them.
Rendering uses PyBullet's CPU renderer (ER_TINY_RENDERER), so it works headless.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as pb
from pybullet_utils.bullet_client import BulletClient

from grits_lab.sim.sim_config import CameraConfig


@dataclass
class CameraImage:
    name: str
    rgb: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) float32 metres
    segmentation: np.ndarray  # (H, W) int32 body ids, -1 background
    intrinsics: np.ndarray  # (3, 3)
    camera_to_world: np.ndarray  # (4, 4)


def intrinsics(cam: CameraConfig) -> np.ndarray:
    fy = cam.height / 2.0 / math.tan(math.radians(cam.fov_deg) / 2.0)
    return np.array([[fy, 0.0, (cam.width - 1) / 2.0], [0.0, fy, (cam.height - 1) / 2.0], [0.0, 0.0, 1.0]])


def camera_to_world(cam: CameraConfig) -> np.ndarray:
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (cam.eye, cam.target, cam.up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, down, forward, eye
    return m


def render(client: BulletClient, cam: CameraConfig) -> CameraImage:
    view = client.computeViewMatrix(cam.eye, cam.target, cam.up)
    proj = client.computeProjectionMatrixFOV(cam.fov_deg, cam.width / cam.height, cam.near, cam.far)
    _, _, rgba, zbuf, seg = client.getCameraImage(cam.width, cam.height, view, proj, renderer=pb.ER_TINY_RENDERER)
    rgb = np.asarray(rgba, dtype=np.uint8).reshape(cam.height, cam.width, 4)[:, :, :3].copy()
    zbuf = np.asarray(zbuf, dtype=np.float64).reshape(cam.height, cam.width)
    depth = cam.far * cam.near / (cam.far - (cam.far - cam.near) * zbuf)
    seg = np.asarray(seg, dtype=np.int64).reshape(cam.height, cam.width)
    seg = np.where(seg < 0, -1, seg & ((1 << 24) - 1)).astype(np.int32)
    return CameraImage(cam.name, rgb, depth.astype(np.float32), seg, intrinsics(cam), camera_to_world(cam))
