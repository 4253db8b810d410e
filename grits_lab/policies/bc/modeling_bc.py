"""The behavior-cloning network: the diffusion policy's observation encoding, then an MLP to the action horizon.

BC sees exactly what the diffusion policy sees (the same encoders, normalizers and observation
handling, borrowed from `DiffusionPolicy` so the two can never drift apart) and differs only in
the head: one deterministic regression of the normalized horizon with an MSE loss, where the
diffusion policy learns a distribution. Multimodal demonstrations average out under BC, which is
the baseline's known weakness and why the paper compares against it.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from grits_lab.config import config_from_dict, config_to_dict
from grits_lab.data.normalize import ActionNormalizer, MinMaxNormalizer
from grits_lab.policies.bc.configuration_bc import BCConfig
from grits_lab.policies.diffusion.obs_encoders import build_obs_encoder
from grits_lab.policies.diffusion.modeling_diffusion import DiffusionPolicy, encoder_obs_keys


class BCPolicy(nn.Module):
    # Observation handling shared with the diffusion policy (same attributes: config.n_obs_steps,
    # config.obs_encoder, obs_encoder, action_normalizer, cloud_normalizer).
    encode_obs = DiffusionPolicy.encode_obs
    _subsample_points = DiffusionPolicy._subsample_points
    obs_to_tensors = DiffusionPolicy.obs_to_tensors
    fit_normalizers = DiffusionPolicy.fit_normalizers
    normalizer_state = DiffusionPolicy.normalizer_state
    load_normalizer_state = DiffusionPolicy.load_normalizer_state

    @property
    def obs_keys(self) -> tuple[str, ...]:
        return encoder_obs_keys(self.config)

    def __init__(self, config: BCConfig) -> None:
        super().__init__()
        self.config = config
        self.obs_encoder: nn.Module | None
        self.obs_encoder, feature_dim = build_obs_encoder(config.obs_encoder, config.n_obs_steps)
        width = feature_dim + config.n_obs_steps * config.action_dim
        layers: list[nn.Module] = []
        for hidden in config.hidden:
            layers += [nn.Linear(width, hidden), nn.LayerNorm(hidden), nn.ReLU(), nn.Dropout(config.dropout)]
            width = hidden
        layers.append(nn.Linear(width, config.horizon * config.action_dim))
        self.head = nn.Sequential(*layers)
        self.action_normalizer = ActionNormalizer()
        self.cloud_normalizer = MinMaxNormalizer(3)

    def forward(self, batch: Mapping[str, torch.Tensor], generator: torch.Generator | None = None) -> torch.Tensor:
        """(B, horizon, 9) normalized actions."""
        cond = self.encode_obs(batch, generator)
        return self.head(cond).view(-1, self.config.horizon, self.config.action_dim)

    def compute_loss(self, batch: Mapping[str, torch.Tensor], generator: torch.Generator | None = None) -> torch.Tensor:
        """MSE between the predicted and the demonstrated normalized horizon."""
        target = self.action_normalizer.normalize(batch["action"].float())
        return F.mse_loss(self(batch, generator), target)

    @torch.no_grad()
    def predict_action(self, obs: Mapping[str, Any]) -> np.ndarray:
        """(n_action_steps, 9) world-frame actions for one observation, (B, n_action_steps, 9) for a batch."""
        single = np.ndim(obs["ee_pose"]) == 2
        was_training = self.training
        self.eval()
        pred = self(self.obs_to_tensors(obs))
        self.train(was_training)
        start = self.config.action_start
        chunk = pred[:, start : start + self.config.n_action_steps]
        actions = self.action_normalizer.unnormalize(chunk.double()).cpu().numpy().astype(np.float32)
        return actions[0] if single else actions

    def policy_state(self) -> dict[str, Any]:
        return {"kind": "bc", "config": config_to_dict(self.config), "model": self.state_dict(), "normalizers": self.normalizer_state()}

    @classmethod
    def from_policy_state(cls, state: Mapping[str, Any], device: str | torch.device = "cpu") -> "BCPolicy":
        policy = cls(config_from_dict(BCConfig, state["config"]))
        policy.load_state_dict(state["model"])
        policy.load_normalizer_state(state["normalizers"])
        return policy.to(device).eval()

    @classmethod
    def load(cls, checkpoint_path: str, device: str | torch.device = "cpu") -> "BCPolicy":
        from grits_lab.errors import StorageError
        from grits_lab.training import load_checkpoint

        ckpt = load_checkpoint(checkpoint_path, map_location=device)
        state = ckpt.get("policy")
        if not isinstance(state, Mapping) or state.get("kind") != "bc":
            raise StorageError(f"{checkpoint_path} is not a behavior-cloning checkpoint")
        return cls.from_policy_state(state, device)
