"""Typed configuration of the diffusion policy: horizons, observation encoder, U-Net and scheduler.

Observation keys the policy reads (each with a leading history axis of `n_obs_steps`, and an
optional batch axis in front):

    ee_pose  (n_obs, 9)            measured spoon pose, world frame (always used)
    cloud    (n_obs, 3, N, 3)      composite cloud, objects ("food", "spoon", "bowl"), world frame
                                   (encoder kind "pointcloud"; any N >= `points_per_object`)
    rgbd     (n_obs, cams, 4, H, W) RGB + depth per camera (encoder kind "rgbd"): float with RGB in
                                   [0, 1] and depth in metres (the demonstration format), or all four
                                   channels uint8 (depth quantized over [0, depth_max])
    past_action (n_obs - 1, 9)     the actions commanded at the previous n_obs - 1 steps, world
                                   frame (only with `inpaint_past_actions`; before the first action,
                                   the spoon's resting pose)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from grits_lab.config import require
from grits_lab.sampling import DDIMConfig


@dataclass
class ObsEncoderConfig:
    """Which observation conditions the policy, and the size of its encoder."""

    kind: Literal["lowdim", "pointcloud", "rgbd"] = "pointcloud"
    # pointcloud (DP3-style: per-point MLP with LayerNorm, max-pool per object, projection)
    points_per_object: int = 128  # points drawn from each object's N points (random in training)
    point_hidden: tuple[int, ...] = (64, 128, 256)
    feature_dim: int = 64  # per observation step, after the projection
    cloud_steps: int = 1  # encode only the newest `cloud_steps` clouds (the scene changes slowly)
    # rgbd (ResNet-18 style with GroupNorm, spatial softmax; 512 features in the authors' code)
    image_size: tuple[int, int] = (240, 320)
    resnet_width: int = 64  # channels of the first stage (64 = ResNet-18)
    resnet_blocks: tuple[int, int, int, int] = (2, 2, 2, 2)
    num_keypoints: int = 32  # spatial-softmax keypoints
    depth_max: float = 2.0  # metres; depth is clipped to [0, depth_max] and scaled to [0, 1]
    cameras: int = 2

    def __post_init__(self) -> None:
        require(self.points_per_object >= 8, "obs_encoder.points_per_object", self.points_per_object, "at least 8")
        require(len(self.point_hidden) >= 1 and min(self.point_hidden) > 0, "obs_encoder.point_hidden", self.point_hidden, "a non-empty list of positive widths")
        require(self.feature_dim > 0, "obs_encoder.feature_dim", self.feature_dim, "positive")
        require(self.cloud_steps >= 1, "obs_encoder.cloud_steps", self.cloud_steps, "at least 1")
        # the trunk downsamples 32x; spatial softmax needs a feature map of at least 2 x 2
        require(min(self.image_size) >= 64, "obs_encoder.image_size", self.image_size, "at least 64 x 64")
        require(self.resnet_width >= 8 and self.resnet_width % 8 == 0, "obs_encoder.resnet_width", self.resnet_width, "a multiple of 8 (GroupNorm groups)")
        require(min(self.resnet_blocks) >= 1, "obs_encoder.resnet_blocks", self.resnet_blocks, "at least 1 block per stage")
        require(self.num_keypoints >= 1, "obs_encoder.num_keypoints", self.num_keypoints, "at least 1")
        require(self.depth_max > 0, "obs_encoder.depth_max", self.depth_max, "positive")
        require(self.cameras >= 1, "obs_encoder.cameras", self.cameras, "at least 1")


@dataclass
class UNetConfig:
    """Conditional 1-D temporal U-Net; authors' sizes: (512, 1024, 2048), kernel 5, 8 groups, 128."""

    down_dims: tuple[int, ...] = (512, 1024, 2048)
    kernel_size: int = 5
    n_groups: int = 8
    diffusion_step_embed_dim: int = 128

    def __post_init__(self) -> None:
        require(len(self.down_dims) >= 1, "unet.down_dims", self.down_dims, "non-empty")
        require(all(d % self.n_groups == 0 for d in self.down_dims), "unet.down_dims", self.down_dims, f"multiples of n_groups={self.n_groups}")
        require(self.kernel_size % 2 == 1, "unet.kernel_size", self.kernel_size, "odd")
        require(self.diffusion_step_embed_dim % 2 == 0, "unet.diffusion_step_embed_dim", self.diffusion_step_embed_dim, "even")


@dataclass
class DiffusionPolicyConfig:
    """The whole policy; defaults are the paper's (authors' code) settings."""

    horizon: int = 16
    n_obs_steps: int = 5
    n_action_steps: int = 12
    action_dim: int = 9
    obs_encoder: ObsEncoderConfig = field(default_factory=ObsEncoderConfig)
    unet: UNetConfig = field(default_factory=UNetConfig)
    scheduler: DDIMConfig = field(default_factory=DDIMConfig)
    # The first n_obs_steps - 1 entries of the horizon are actions already executed. When set,
    # training feeds them to the U-Net clean (not noised, not in the loss) and planning holds them
    # at the commanded values at every denoising step (Diffusion Policy's inpainting conditioning,
    # applied to the past actions), so each new chunk continues from where the last one left the
    # spoon instead of jumping to another demonstration's path at the chunk boundary.
    inpaint_past_actions: bool = False

    def __post_init__(self) -> None:
        require(self.n_obs_steps >= 1, "n_obs_steps", self.n_obs_steps, "at least 1")
        require(self.n_action_steps >= 1, "n_action_steps", self.n_action_steps, "at least 1")
        require(
            self.n_obs_steps - 1 + self.n_action_steps <= self.horizon,
            "horizon",
            self.horizon,
            f">= n_obs_steps - 1 + n_action_steps = {self.n_obs_steps - 1 + self.n_action_steps}",
        )
        levels = len(self.unet.down_dims) - 1
        require(self.horizon % (2**levels) == 0, "horizon", self.horizon, f"divisible by 2^(len(down_dims) - 1) = {2**levels}")
        require(self.action_dim == 9, "action_dim", self.action_dim, "9 (xyz + 6-D rotation)")
        require(
            self.obs_encoder.cloud_steps <= self.n_obs_steps,
            "obs_encoder.cloud_steps",
            self.obs_encoder.cloud_steps,
            f"at most n_obs_steps={self.n_obs_steps}",
        )

    @property
    def action_start(self) -> int:
        """Index in the horizon of the first executed action (the current step)."""
        return self.n_obs_steps - 1

    @property
    def n_past_actions(self) -> int:
        """How many executed actions each plan is conditioned on (0 without inpainting)."""
        return self.action_start if self.inpaint_past_actions else 0
