"""Typed configuration of the behavior-cloning baseline; horizon names match the diffusion policy's."""

from __future__ import annotations

from dataclasses import dataclass, field

from grits_lab.config import require
from grits_lab.policies.diffusion.configuration_diffusion import ObsEncoderConfig


@dataclass
class BCConfig:
    """Same observations as the diffusion policy (history of spoon poses + cloud or RGB-D features);
    an MLP regresses the whole horizon, of which the chunk [n_obs_steps - 1, + n_action_steps) runs."""

    horizon: int = 16
    n_obs_steps: int = 5
    n_action_steps: int = 12
    action_dim: int = 9
    obs_encoder: ObsEncoderConfig = field(default_factory=ObsEncoderConfig)
    hidden: tuple[int, ...] = (512, 512)
    dropout: float = 0.1

    def __post_init__(self) -> None:
        require(self.n_obs_steps >= 1, "n_obs_steps", self.n_obs_steps, "at least 1")
        require(self.n_action_steps >= 1, "n_action_steps", self.n_action_steps, "at least 1")
        require(self.n_obs_steps - 1 + self.n_action_steps <= self.horizon, "horizon", self.horizon,
                f">= n_obs_steps - 1 + n_action_steps = {self.n_obs_steps - 1 + self.n_action_steps}")
        require(self.action_dim == 9, "action_dim", self.action_dim, "9 (xyz + 6-D rotation)")
        require(len(self.hidden) >= 1 and min(self.hidden) > 0, "hidden", self.hidden, "a non-empty list of positive widths")
        require(0 <= self.dropout < 1, "dropout", self.dropout, "in [0, 1)")
        require(self.obs_encoder.cloud_steps <= self.n_obs_steps, "obs_encoder.cloud_steps", self.obs_encoder.cloud_steps,
                f"at most n_obs_steps={self.n_obs_steps}")

    @property
    def action_start(self) -> int:
        return self.n_obs_steps - 1
