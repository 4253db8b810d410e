"""The spillage predictor f_spillage(A_t, P_t) -> P(spill) (contract 7) and its cloud normalization.

`SpillagePredictor` = point encoder on the composite cloud + per-waypoint trajectory MLP + fusion
MLP + 2-way softmax. The cloud embedding does not depend on the trajectory, so a guided sampler
calls `encode_cloud` once per plan and `logits`/`spill_probability` at every guided step; both are
differentiable with respect to the trajectory, which is given in the predictor's normalized
action space (`grits_lab.spillage.guidance_objective` maps a policy's space into it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

from grits_lab.errors import InputError, StorageError
from grits_lab.perception.composite import CLOUD_OBJECTS
from grits_lab.spillage.predictor_config import PredictorModelConfig
from grits_lab.spillage.cloud_encoders import DP3Encoder, PointNet2Encoder

N_OBJECTS = len(CLOUD_OBJECTS)  # objects of the composite cloud (food, spoon, bowl)
BOWL = CLOUD_OBJECTS.index("bowl")  # the source bowl's index in the cloud


class CloudNormalizer:
    """World-frame cloud -> (cloud - centre) / scale, with `centre` the source bowl's centre.

    Why a fixed reference and not each cloud's own centroid: the trajectory is in the world
    frame, and what decides a spill is where the spoon goes relative to the bowl rim and the
    food. A per-cloud centroid moves with the food and the spoon, so the same trajectory would
    meet different coordinates from sample to sample. The source bowl is fixed in the scene,
    so its mean point (fitted once on the training clouds) is a stable origin, and one
    isotropic scale (the bowl's size) keeps the geometry undistorted, unlike per-axis min-max.
    """

    def __init__(self, centre: Any = (0.0, 0.0, 0.0), scale: float = 0.1) -> None:
        self.centre = np.asarray(centre, dtype=np.float64).reshape(3)
        self.scale = float(scale)

    def fit(self, clouds: np.ndarray) -> "CloudNormalizer":
        """`clouds` (..., K, N, 3) world frame: the centre becomes the mean of the bowl points."""
        clouds = np.asarray(clouds, dtype=np.float64)
        if clouds.ndim < 3 or clouds.shape[-3] != N_OBJECTS or clouds.shape[-1] != 3:
            raise InputError(f"clouds must have shape (..., {N_OBJECTS}, N, 3); got {clouds.shape}")
        bowl = clouds[..., BOWL, :, :].reshape(-1, 3)
        if not np.all(np.isfinite(bowl)):
            raise InputError("cannot fit the cloud normalizer: bowl points contain NaN or inf")
        self.centre = bowl.mean(axis=0)
        return self

    def normalize(self, cloud: Any) -> Any:
        if isinstance(cloud, torch.Tensor):
            return (cloud - torch.as_tensor(self.centre, dtype=cloud.dtype, device=cloud.device)) / self.scale
        return ((np.asarray(cloud, dtype=np.float32) - self.centre.astype(np.float32)) / np.float32(self.scale)).astype(np.float32)

    def state_dict(self) -> dict[str, Any]:
        return {"centre": self.centre.tolist(), "scale": self.scale}

    def load_state_dict(self, state: dict[str, Any]) -> "CloudNormalizer":
        try:
            self.centre = np.asarray(state["centre"], dtype=np.float64).reshape(3)
            self.scale = float(state["scale"])
        except (KeyError, TypeError, ValueError) as exc:
            raise StorageError(f"invalid cloud normalizer state: {exc}") from None
        return self


class SpillagePredictor(nn.Module):
    """f_spillage: (normalized trajectory chunk `(B, L, 9)`, normalized cloud `(B, 3, N, 3)`) -> logits `(B, 2)`.

    `config.inputs` selects GRITS ("trajectory_and_cloud") or a baseline: "trajectory" has no
    cloud encoder (its embedding is empty), "cloud" ignores the trajectory (zero gradient).
    Class 1 is "spill".
    """

    def __init__(self, config: PredictorModelConfig) -> None:
        super().__init__()
        self.config = config
        self.uses_cloud = config.inputs != "trajectory"
        self.uses_trajectory = config.inputs != "cloud"
        self.encoder: nn.Module | None = None
        cloud_dim = 0
        if self.uses_cloud:
            self.encoder = DP3Encoder(config.dp3, N_OBJECTS) if config.encoder == "dp3" else PointNet2Encoder(config.pointnet2, N_OBJECTS)
            cloud_dim = self.encoder.out_dim
        traj_dim = 0
        self.waypoint_mlp: nn.Module | None = None
        if self.uses_trajectory:
            layers: list[nn.Module] = []
            d_in = config.action_dim
            for d_out in config.waypoint_mlp:
                layers += [nn.Linear(d_in, d_out), nn.ReLU()]
                d_in = d_out
            self.waypoint_mlp = nn.Sequential(*layers)
            traj_dim = config.n_action_steps * d_in
        fusion: list[nn.Module] = []
        d_in = cloud_dim + traj_dim
        for d_out in config.fusion_mlp:
            fusion += [nn.Linear(d_in, d_out), nn.ReLU(), nn.Dropout(config.dropout)]
            d_in = d_out
        fusion.append(nn.Linear(d_in, 2))
        self.fusion = nn.Sequential(*fusion)
        self.cloud_dim = cloud_dim

    def encode_cloud(self, cloud_norm: torch.Tensor) -> torch.Tensor:
        """(B, 3, N, 3) normalized cloud -> (B, D) embedding; D = 0 for the trajectory-only baseline."""
        if self.encoder is None:
            return cloud_norm.new_zeros(cloud_norm.shape[0], 0)
        return self.encoder(cloud_norm)

    def logits(self, traj_norm: torch.Tensor, cloud_embedding: torch.Tensor) -> torch.Tensor:
        """(B, L, 9) normalized trajectory chunk + (B, D) embedding -> (B, 2) logits (no spill, spill).

        An embedding of batch 1 is broadcast over a trajectory batch (one cloud, many candidates).
        """
        L, dim = self.config.n_action_steps, self.config.action_dim
        if traj_norm.ndim != 3 or traj_norm.shape[1:] != (L, dim):
            raise ValueError(f"trajectory must have shape (B, {L}, {dim}); got {tuple(traj_norm.shape)}")
        b = traj_norm.shape[0]
        if cloud_embedding.shape[0] == 1 and b > 1:
            cloud_embedding = cloud_embedding.expand(b, -1)
        parts = []
        if self.uses_cloud:
            parts.append(cloud_embedding)
        if self.uses_trajectory:
            assert self.waypoint_mlp is not None
            parts.append(self.waypoint_mlp(traj_norm).flatten(1))
        return self.fusion(torch.cat(parts, dim=1))

    def spill_probability(self, traj_norm: torch.Tensor, cloud_embedding: torch.Tensor) -> torch.Tensor:
        """(B,) P(spill) = softmax(logits)[:, 1]."""
        return torch.softmax(self.logits(traj_norm, cloud_embedding), dim=-1)[:, 1]

    def forward(self, traj_norm: torch.Tensor, cloud_norm: torch.Tensor) -> torch.Tensor:
        return self.logits(traj_norm, self.encode_cloud(cloud_norm))
