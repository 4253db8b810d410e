"""The guidance objective of contract 8: P(spill) of the executed chunk of a normalized action horizon.

A guided sampler denoises a whole horizon (B, horizon, 9) in the policy's normalized action space,
but only the chunk it will execute, horizon indices [n_obs_steps - 1, n_obs_steps - 1 +
n_action_steps), is what the predictor judges. `SpillageObjective` slices that chunk, maps it
affinely from the policy normalizer's space into the predictor's (the identity when both were
fitted on the same data) and returns P(spill), differentiably, with the cloud encoded once.
"""

from __future__ import annotations

from typing import Any

import torch

from grits_lab.data.normalize import MinMaxNormalizer
from grits_lab.errors import InputError
from grits_lab.spillage.predictor_checkpoint import TrainedPredictor


def policy_to_predictor_affine(policy_normalizer: MinMaxNormalizer | None, predictor: TrainedPredictor) -> tuple[torch.Tensor, torch.Tensor]:
    """`(scale, offset)` (9,) with traj_predictor = traj_policy * scale + offset; identity for None."""
    if policy_normalizer is None:
        return torch.ones(9), torch.zeros(9)
    scale, offset = policy_normalizer.relative_affine(predictor.action_normalizer)
    return torch.as_tensor(scale, dtype=torch.float32), torch.as_tensor(offset, dtype=torch.float32)


def to_predictor_space(traj_policy_norm: torch.Tensor, scale: torch.Tensor, offset: torch.Tensor) -> torch.Tensor:
    """(..., 9) in the policy's normalized space -> the predictor's; affine, so the gradient flows."""
    return traj_policy_norm * scale.to(traj_policy_norm) + offset.to(traj_policy_norm)


class SpillageObjective:
    """`objective(traj_norm (B, horizon, 9)) -> (B,)` P(spill) of the executed chunk, for a guided sampler.

    `cloud_world` (3, N, 3) or (1, 3, N, 3) is the composite cloud observed now (world frame); it is
    encoded once, here. `policy_normalizer` is the policy's ActionNormalizer (None when the
    trajectory is already in the predictor's space).
    """

    def __init__(self, predictor: TrainedPredictor, cloud_world: Any, policy_normalizer: MinMaxNormalizer | None = None, n_obs_steps: int = 5, n_action_steps: int = 12) -> None:
        if n_action_steps != predictor.config.model.n_action_steps:
            raise InputError(f"the predictor judges chunks of {predictor.config.model.n_action_steps} actions; the policy executes {n_action_steps}")
        if n_obs_steps < 1:
            raise InputError(f"`n_obs_steps` must be at least 1. Got {n_obs_steps}.")
        self.predictor = predictor
        self.start = n_obs_steps - 1
        self.n_action_steps = n_action_steps
        self.scale, self.offset = policy_to_predictor_affine(policy_normalizer, predictor)
        self.embedding = predictor.encode_cloud(cloud_world)

    def executed_chunk(self, traj_norm: torch.Tensor) -> torch.Tensor:
        """(B, horizon, 9) -> (B, n_action_steps, 9), the executed slice, in the predictor's space."""
        if traj_norm.ndim != 3 or traj_norm.shape[-1] != 9:
            raise InputError(f"trajectory must have shape (B, horizon, 9); got {tuple(traj_norm.shape)}")
        end = self.start + self.n_action_steps
        if traj_norm.shape[1] < end:
            raise InputError(f"horizon {traj_norm.shape[1]} is shorter than n_obs_steps - 1 + n_action_steps = {end}")
        return to_predictor_space(traj_norm[:, self.start : end], self.scale, self.offset)

    def __call__(self, traj_norm: torch.Tensor) -> torch.Tensor:
        return self.predictor.spill_probability(self.executed_chunk(traj_norm), self.embedding.to(traj_norm))
