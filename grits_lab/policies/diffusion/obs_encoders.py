"""Observation encoders of the diffusion policy: composite point cloud (DP3-style) and RGB-D (ResNet-18 style).

Each encoder maps one observation step to a feature vector; the policy concatenates the
features of the history with the normalized spoon pose to form the U-Net's condition.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from grits_lab.perception.composite import CLOUD_OBJECTS
from grits_lab.policies.diffusion.configuration_diffusion import ObsEncoderConfig


class PointCloudEncoder(nn.Module):
    """DP3-style encoder: per-point MLP with LayerNorm (no T-Net, no BatchNorm), max-pool per object.

    Input (B, K, N, 3) normalized points of K objects; each point gets its object's one-hot so
    the shared MLP knows food from spoon from bowl; pooling per object keeps that distinction in
    the output. Output (B, feature_dim).
    """

    def __init__(self, config: ObsEncoderConfig, n_objects: int = len(CLOUD_OBJECTS)) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        width = 3 + n_objects
        for hidden in config.point_hidden:
            layers += [nn.Linear(width, hidden), nn.LayerNorm(hidden), nn.ReLU()]
            width = hidden
        self.point_mlp = nn.Sequential(*layers)
        self.projection = nn.Sequential(nn.Linear(n_objects * width, config.feature_dim), nn.LayerNorm(config.feature_dim))
        self.register_buffer("object_onehot", torch.eye(n_objects), persistent=False)
        self.n_objects = n_objects

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        b, k, n, _ = points.shape
        if k != self.n_objects:
            raise ValueError(f"expected {self.n_objects} objects in the cloud, got {k}")
        onehot = self.object_onehot[None, :, None, :].expand(b, k, n, k)
        h = self.point_mlp(torch.cat([points, onehot], dim=-1))  # (B, K, N, C)
        return self.projection(h.amax(dim=2).flatten(1))


class SpatialSoftmax(nn.Module):
    """(B, C, H, W) -> (B, 2K): expected image coordinates of K learned keypoint maps."""

    def __init__(self, channels: int, num_keypoints: int) -> None:
        super().__init__()
        self.keypoints = nn.Conv2d(channels, num_keypoints, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        maps = self.keypoints(x)
        b, k, h, w = maps.shape
        attention = F.softmax(maps.flatten(2), dim=-1).view(b, k, h, w)
        ys = torch.linspace(-1, 1, h, device=x.device, dtype=x.dtype)
        xs = torch.linspace(-1, 1, w, device=x.device, dtype=x.dtype)
        ex = (attention.sum(dim=2) * xs).sum(-1)
        ey = (attention.sum(dim=3) * ys).sum(-1)
        return torch.stack([ex, ey], dim=-1).flatten(1)


class BasicBlock(nn.Module):
    def __init__(self, c_in: int, c_out: int, stride: int) -> None:
        super().__init__()
        groups = lambda c: max(1, c // 16)  # GroupNorm with 16 channels per group, as in robomimic
        self.body = nn.Sequential(
            nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False),
            nn.GroupNorm(groups(c_out), c_out),
            nn.ReLU(inplace=True),
            nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False),
            nn.GroupNorm(groups(c_out), c_out),
        )
        self.skip = (
            nn.Sequential(nn.Conv2d(c_in, c_out, 1, stride, bias=False), nn.GroupNorm(groups(c_out), c_out))
            if stride != 1 or c_in != c_out
            else nn.Identity()
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.body(x) + self.skip(x))


class RGBDEncoder(nn.Module):
    """ResNet-18 layout from scratch, 4 input channels, GroupNorm, spatial-softmax pooling.

    Input (B, cams, 4, H, W) float in [0, 1]; one shared trunk over cameras; output
    (B, feature_dim) from the concatenated keypoints of all cameras.
    """

    def __init__(self, config: ObsEncoderConfig) -> None:
        super().__init__()
        w = config.resnet_width
        self.stem = nn.Sequential(
            nn.Conv2d(4, w, 7, 2, 3, bias=False), nn.GroupNorm(max(1, w // 16), w), nn.ReLU(inplace=True), nn.MaxPool2d(3, 2, 1)
        )
        stages: list[nn.Module] = []
        c_in = w
        for i, n_blocks in enumerate(config.resnet_blocks):
            c_out = w * 2**i
            for j in range(n_blocks):
                stages.append(BasicBlock(c_in, c_out, 2 if (j == 0 and i > 0) else 1))
                c_in = c_out
        self.trunk = nn.Sequential(*stages)
        self.pool = SpatialSoftmax(c_in, config.num_keypoints)
        self.projection = nn.Linear(config.cameras * 2 * config.num_keypoints, config.feature_dim)
        self.image_size = tuple(config.image_size)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        b, cams = images.shape[:2]
        x = images.flatten(0, 1)
        if tuple(x.shape[-2:]) != self.image_size:
            x = F.interpolate(x, size=self.image_size, mode="bilinear", align_corners=False)
        feats = self.pool(self.trunk(self.stem(x)))
        return self.projection(feats.view(b, -1))


def rgbd_to_unit(rgbd: torch.Tensor, depth_max: float) -> torch.Tensor:
    """(..., 4, H, W) stored RGB-D -> float in [0, 1]: RGB as is, depth clipped to depth_max and scaled.

    Float input follows the demonstration format (grits_lab/collection/demos.py): RGB in [0, 1], depth
    in metres. uint8 input is read as four 0-255 channels (depth already quantized over [0, depth_max]).
    """
    if rgbd.dtype == torch.uint8:
        return rgbd.float() / 255.0
    x = rgbd.float()
    depth = x[..., 3:, :, :].clamp(0, depth_max) / depth_max
    return torch.cat([x[..., :3, :, :].clamp(0, 1), depth], dim=-3)


def build_obs_encoder(enc: ObsEncoderConfig, n_obs_steps: int) -> tuple[nn.Module | None, int]:
    """The observation encoder a policy's config names and the width of its features over the history.

    Returns (encoder, feature_dim): a `PointCloudEncoder` reading `enc.cloud_steps` clouds, an
    `RGBDEncoder` reading `n_obs_steps` images, or (None, 0) for `kind: none` (the spoon pose only).
    """
    if enc.kind == "pointcloud":
        return PointCloudEncoder(enc), enc.cloud_steps * enc.feature_dim
    if enc.kind == "rgbd":
        return RGBDEncoder(enc), n_obs_steps * enc.feature_dim
    return None, 0
