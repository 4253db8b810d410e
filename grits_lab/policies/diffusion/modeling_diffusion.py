"""The diffusion policy: observation encoding, the noise-prediction loss, and planning with an injected sampler.

The policy owns its normalizers (actions and spoon poses share one `ActionNormalizer`; cloud
points have their own min-max) and saves them with its weights. Sampling is delegated to a
sampler (grits_lab/sampling): the plain DDIM sampler by default, or a guided / post-hoc one
passed at call time, so guidance never touches the network.

Observation dict (see configuration_diffusion.py): `ee_pose` (n_obs, 9), `cloud`
(n_obs, 3, N, 3) or `rgbd` (n_obs, cams, 4, H, W), with an optional leading batch axis.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from grits_lab.config import config_from_dict, config_to_dict
from grits_lab.data.normalize import ActionNormalizer, MinMaxNormalizer
from grits_lab.errors import InputError
from grits_lab.policies.diffusion.configuration_diffusion import DiffusionPolicyConfig
from grits_lab.policies.diffusion.obs_encoders import build_obs_encoder, rgbd_to_unit
from grits_lab.policies.diffusion.unet import ConditionalUnet1D
from grits_lab.sampling import DDIMSampler, DDIMScheduler, Objective, Sampler, SampleResult


def encoder_obs_keys(config: Any) -> tuple[str, ...]:
    """The observation keys the encoders read: the spoon pose and the encoder's sensor."""
    kind = config.obs_encoder.kind
    return ("ee_pose",) + (("cloud",) if kind == "pointcloud" else ("rgbd",) if kind == "rgbd" else ())


@dataclass
class Plan:
    """One planning call: executed actions (world frame), the whole normalized horizon, diagnostics."""

    actions: np.ndarray  # (B, n_action_steps, 9) world frame
    trajectory_norm: torch.Tensor  # (B, horizon, 9) normalized action space (what guidance saw)
    result: SampleResult


class DiffusionPolicy(nn.Module):
    def __init__(self, config: DiffusionPolicyConfig) -> None:
        super().__init__()
        self.config = config
        self.obs_encoder: nn.Module | None
        self.obs_encoder, feature_dim = build_obs_encoder(config.obs_encoder, config.n_obs_steps)
        self.global_cond_dim = feature_dim + config.n_obs_steps * config.action_dim
        u = config.unet
        self.model = ConditionalUnet1D(
            config.action_dim, self.global_cond_dim, tuple(u.down_dims), u.kernel_size, u.n_groups, u.diffusion_step_embed_dim
        )
        self.noise_scheduler = DDIMScheduler(config.scheduler)
        self.sampler: Sampler = DDIMSampler(self.noise_scheduler)
        self.action_normalizer = ActionNormalizer()
        self.cloud_normalizer = MinMaxNormalizer(3)

    # ------------------------------------------------------------------ normalizers
    @property
    def obs_keys(self) -> tuple[str, ...]:
        return encoder_obs_keys(self.config) + (("past_action",) if self.config.n_past_actions else ())

    def fit_normalizers(self, actions: np.ndarray, ee_poses: np.ndarray, cloud_points: np.ndarray | None = None) -> None:
        """Fit on training data: poses and actions share one range so both land in [-1, 1]."""
        self.action_normalizer.fit(np.concatenate([actions.reshape(-1, 9), ee_poses.reshape(-1, 9)]))
        if cloud_points is not None:
            self.cloud_normalizer.fit(cloud_points.reshape(-1, 3))

    def normalizer_state(self) -> dict[str, Any]:
        state = {"action": self.action_normalizer.state_dict()}
        if self.cloud_normalizer.fitted:
            state["cloud"] = self.cloud_normalizer.state_dict()
        return state

    def load_normalizer_state(self, state: Mapping[str, Any]) -> None:
        self.action_normalizer.load_state_dict(state["action"])
        if "cloud" in state:
            self.cloud_normalizer.load_state_dict(state["cloud"])

    # ------------------------------------------------------------------ conditioning
    def encode_obs(self, obs: Mapping[str, torch.Tensor], generator: torch.Generator | None = None) -> torch.Tensor:
        """Batched observation tensors (B, n_obs, ...) in world units -> (B, global_cond_dim)."""
        cfg = self.config
        pose = obs["ee_pose"]
        if pose.shape[1:] != (cfg.n_obs_steps, 9):
            raise InputError(f"`ee_pose` must have shape (B, {cfg.n_obs_steps}, 9); got {tuple(pose.shape)}")
        feats = [self.action_normalizer.normalize(pose.float()).flatten(1)]
        kind = cfg.obs_encoder.kind
        if kind == "pointcloud":
            cloud = obs["cloud"][:, -cfg.obs_encoder.cloud_steps :].float()  # (B, S, 3, N, 3)
            b, s, k, n, _ = cloud.shape
            cloud = self._subsample_points(cloud.flatten(0, 1), generator)  # (B*S, 3, n, 3)
            feats.insert(0, self.obs_encoder(self.cloud_normalizer.normalize(cloud)).view(b, -1))  # type: ignore[misc]
        elif kind == "rgbd":
            images = rgbd_to_unit(obs["rgbd"], cfg.obs_encoder.depth_max)  # (B, T, cams, 4, H, W)
            b, t = images.shape[:2]
            feats.insert(0, self.obs_encoder(images.flatten(0, 1)).view(b, -1))  # type: ignore[misc]
        return torch.cat(feats, dim=-1)

    def _subsample_points(self, cloud: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
        """(M, K, N, 3) -> (M, K, n, 3): random points in training (augmentation), evenly spaced otherwise."""
        n_total, n = cloud.shape[2], self.config.obs_encoder.points_per_object
        if n_total < n:
            raise InputError(f"cloud has {n_total} points per object; the policy needs at least {n}")
        if n_total == n:
            return cloud
        if self.training:
            scores = torch.rand(cloud.shape[:3], generator=generator, device=cloud.device)
            idx = scores.argsort(dim=-1)[..., :n]
            return torch.gather(cloud, 2, idx[..., None].expand(-1, -1, -1, 3))
        idx = torch.linspace(0, n_total - 1, n, device=cloud.device).round().long()
        return cloud[:, :, idx]

    # ------------------------------------------------------------------ training
    def compute_loss(self, batch: Mapping[str, torch.Tensor], generator: torch.Generator | None = None) -> torch.Tensor:
        """Epsilon-prediction MSE on a batch: `action` (B, horizon, 9) world frame + observation keys."""
        actions = self.action_normalizer.normalize(batch["action"].float())
        cond = self.encode_obs(batch, generator)
        noise = torch.randn(actions.shape, generator=generator, device=actions.device)
        t = torch.randint(0, self.config.scheduler.num_train_timesteps, (actions.shape[0],), generator=generator, device=actions.device)
        noisy = self.noise_scheduler.add_noise(actions, noise, t)
        k = self.config.n_past_actions
        noisy = _inpaint(noisy, actions[:, :k])
        pred = self.model(noisy, t, cond)
        target = noise if self.config.scheduler.prediction_type == "epsilon" else actions
        return F.mse_loss(pred[:, k:], target[:, k:])

    # ------------------------------------------------------------------ inference
    def plan(
        self,
        obs: Mapping[str, Any],
        *,
        sampler: Sampler | None = None,
        objective: Objective | None = None,
        generator: torch.Generator | None = None,
    ) -> Plan:
        """Sample a horizon for each observation in the batch and cut out the executed chunk."""
        batch = self.obs_to_tensors(obs)
        device = next(self.parameters()).device
        with torch.no_grad():
            cond = self.encode_obs(batch)
        model = self.model
        known = self.action_normalizer.normalize(batch["past_action"].float()) if self.config.n_past_actions else None
        denoise = lambda x, t: model(_inpaint(x, known), t, cond)
        shape = (cond.shape[0], self.config.horizon, self.config.action_dim)
        result = (sampler or self.sampler).sample(denoise, shape, generator=generator, objective=objective, device=device)
        result.sample = _inpaint(result.sample, known)
        start = self.config.action_start
        chunk = result.sample[:, start : start + self.config.n_action_steps]
        actions = self.action_normalizer.unnormalize(chunk.detach().double()).cpu().numpy().astype(np.float32)
        return Plan(actions, result.sample, result)

    def predict_action(
        self,
        obs: Mapping[str, Any],
        *,
        sampler: Sampler | None = None,
        objective: Objective | None = None,
        generator: torch.Generator | None = None,
    ) -> np.ndarray:
        """(n_action_steps, 9) world-frame actions for one observation, (B, n_action_steps, 9) for a batch."""
        single = np.ndim(obs["ee_pose"]) == 2
        actions = self.plan(obs, sampler=sampler, objective=objective, generator=generator).actions
        return actions[0] if single else actions

    def obs_to_tensors(self, obs: Mapping[str, Any]) -> dict[str, torch.Tensor]:
        """Numpy or torch observations, single or batched -> batched tensors on the model's device."""
        device = next(self.parameters()).device
        missing = [k for k in self.obs_keys if k not in obs]
        if missing:
            raise InputError(f"observation is missing {missing}; this policy reads {list(self.obs_keys)}")
        single = np.ndim(obs["ee_pose"]) == 2
        out = {}
        for key in self.obs_keys:
            value = obs[key]
            tensor = value if isinstance(value, torch.Tensor) else torch.from_numpy(np.asarray(value))
            if tensor.dtype == torch.float16 or tensor.dtype == torch.float64:
                tensor = tensor.float()
            if tensor.is_floating_point() and not torch.isfinite(tensor).all():
                raise InputError(f"observation `{key}` contains NaN or inf")
            out[key] = (tensor[None] if single else tensor).to(device)
        return out

    # ------------------------------------------------------------------ persistence
    def policy_state(self) -> dict[str, Any]:
        """Everything needed to rebuild this policy: config, weights, normalizers."""
        return {"config": config_to_dict(self.config), "model": self.state_dict(), "normalizers": self.normalizer_state()}

    @classmethod
    def from_policy_state(cls, state: Mapping[str, Any], device: str | torch.device = "cpu") -> "DiffusionPolicy":
        policy = cls(config_from_dict(DiffusionPolicyConfig, state["config"]))
        policy.load_state_dict(state["model"])
        policy.load_normalizer_state(state["normalizers"])
        return policy.to(device).eval()

    @classmethod
    def load(cls, checkpoint_path: str, device: str | torch.device = "cpu", use_ema: bool = True) -> "DiffusionPolicy":
        """A trained policy from a training checkpoint; EMA weights unless `use_ema` is False."""
        from grits_lab.training import load_checkpoint

        ckpt = load_checkpoint(checkpoint_path, map_location=device)
        state = dict(ckpt["policy"])
        if use_ema and ckpt.get("ema") is not None:
            state["model"] = ckpt["ema"]["model"]
        return cls.from_policy_state(state, device)


def _inpaint(trajectory: torch.Tensor, known: torch.Tensor | None) -> torch.Tensor:
    """`trajectory` (B, H, D) with its first entries replaced by `known` (B, k, D); unchanged when k = 0."""
    if known is None or known.shape[1] == 0:
        return trajectory
    return torch.cat([known.to(trajectory.dtype), trajectory[:, known.shape[1] :]], dim=1)
