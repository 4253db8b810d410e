"""DDIM scheduler (Song et al., 2021) in the diffusers style: `set_timesteps(n)`, then `step(...)` per timestep.

Symbols, as in the DDIM paper and GRITS Algorithm 1 (t is the index on the training scale):

    alpha_bar_t  `alphas_cumprod[t]`, the product of (1 - beta_i) for i <= t
    x_t / A_t    `sample`, the noisy action trajectory
    eps_theta    `model_output`, the predicted noise (epsilon prediction)
    x_0|t        `pred_original_sample` = (x_t - sqrt(1 - alpha_bar_t) eps) / sqrt(alpha_bar_t)
    x_{t-1}      `prev_sample` = sqrt(alpha_bar_prev) x_0|t + sqrt(1 - alpha_bar_prev - sigma^2) eps
                 + sigma z,  sigma = eta * sqrt((1 - alpha_bar_prev)/(1 - alpha_bar_t)) * sqrt(1 - alpha_bar_t/alpha_bar_prev)

Training uses T = `num_train_timesteps` (100 in GRITS) and `add_noise`; sampling visits
`num_inference_steps` (16) timesteps spaced "leading" as diffusers does: t = 90, 84, ..., 6, 0
for 100/16, so a guidance threshold s = 30 on the training scale covers the last 6 steps.
The scheduler knows nothing about networks or guidance (grits_lab/sampling/guidance.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
import torch

from grits_lab.config import require


@dataclass
class DDIMConfig:
    """Noise schedule and sampler settings; defaults are the authors' (diffusion_policy's DDIM)."""

    num_train_timesteps: int = 100
    num_inference_steps: int = 16
    beta_schedule: Literal["squaredcos_cap_v2", "linear"] = "squaredcos_cap_v2"
    beta_start: float = 0.0001  # only for the linear schedule
    beta_end: float = 0.02
    clip_sample: bool = True  # clip x_0|t to [-clip_sample_range, clip_sample_range] (actions live in [-1, 1])
    clip_sample_range: float = 1.0
    prediction_type: Literal["epsilon", "sample"] = "epsilon"
    set_alpha_to_one: bool = True  # alpha_bar before t = 0 is 1, so the last step returns x_0|0
    eta: float = 0.0  # 0 = deterministic DDIM; 1 = DDPM-like variance

    def __post_init__(self) -> None:
        require(self.num_train_timesteps >= 2, "num_train_timesteps", self.num_train_timesteps, "at least 2")
        require(
            1 <= self.num_inference_steps <= self.num_train_timesteps,
            "num_inference_steps",
            self.num_inference_steps,
            f"in [1, num_train_timesteps={self.num_train_timesteps}]",
        )
        require(0 < self.beta_start < self.beta_end < 1, "beta_start/beta_end", (self.beta_start, self.beta_end), "0 < beta_start < beta_end < 1")
        require(self.clip_sample_range > 0, "clip_sample_range", self.clip_sample_range, "positive")
        require(self.eta >= 0, "eta", self.eta, "non-negative")


class DDIMStepOutput(NamedTuple):
    prev_sample: torch.Tensor  # x_{t-1}, (B, H, D)
    pred_original_sample: torch.Tensor  # x_0|t after optional clipping, (B, H, D)


def squared_cosine_betas(num_timesteps: int, max_beta: float = 0.999) -> np.ndarray:
    """Betas of the squared-cosine schedule (Nichol & Dhariwal, 2021), s = 0.008, capped at `max_beta`."""

    def alpha_bar(u: float) -> float:
        return math.cos((u + 0.008) / 1.008 * math.pi / 2) ** 2

    return np.array(
        [min(1 - alpha_bar((i + 1) / num_timesteps) / alpha_bar(i / num_timesteps), max_beta) for i in range(num_timesteps)],
        dtype=np.float64,
    )


class DDIMScheduler:
    """Deterministic (eta = 0) or stochastic DDIM over a fixed training schedule."""

    def __init__(self, config: DDIMConfig | None = None) -> None:
        self.config = config or DDIMConfig()
        c = self.config
        if c.beta_schedule == "squaredcos_cap_v2":
            betas = squared_cosine_betas(c.num_train_timesteps)
        else:
            betas = np.linspace(c.beta_start, c.beta_end, c.num_train_timesteps, dtype=np.float64)
        self.betas = torch.tensor(betas, dtype=torch.float32)
        self.alphas_cumprod = torch.tensor(np.cumprod(1.0 - betas), dtype=torch.float32)
        self.final_alpha_cumprod = torch.tensor(1.0) if c.set_alpha_to_one else self.alphas_cumprod[0]
        self.num_inference_steps = 0
        self.timesteps = torch.empty(0, dtype=torch.long)
        self.set_timesteps(c.num_inference_steps)

    @property
    def step_ratio(self) -> int:
        return self.config.num_train_timesteps // self.num_inference_steps

    def set_timesteps(self, num_inference_steps: int) -> None:
        """Choose the visited timesteps, descending: (n - 1) * r, ..., r, 0 with r = T // n."""
        if not 1 <= num_inference_steps <= self.config.num_train_timesteps:
            raise ValueError(
                f"`num_inference_steps` must be in [1, {self.config.num_train_timesteps}]. Got {num_inference_steps}."
            )
        self.num_inference_steps = int(num_inference_steps)
        ratio = self.config.num_train_timesteps // self.num_inference_steps
        self.timesteps = torch.arange(self.num_inference_steps - 1, -1, -1, dtype=torch.long) * ratio

    def alpha_bar(self, timestep: int) -> torch.Tensor:
        """alpha_bar_t on the training scale; t < 0 means "before the first step" (the final alpha)."""
        return self.alphas_cumprod[timestep] if timestep >= 0 else self.final_alpha_cumprod

    def predict_original(self, model_output: torch.Tensor, timestep: int, sample: torch.Tensor) -> torch.Tensor:
        """x_0|t from the model output, without clipping (the A_{0|k} of GRITS Algorithm 1)."""
        if self.config.prediction_type == "sample":
            return model_output
        ab = self.alpha_bar(int(timestep)).to(sample.device, sample.dtype)
        return (sample - torch.sqrt(1 - ab) * model_output) / torch.sqrt(ab)

    def step(
        self,
        model_output: torch.Tensor,
        timestep: int | torch.Tensor,
        sample: torch.Tensor,
        generator: torch.Generator | None = None,
    ) -> DDIMStepOutput:
        """One reverse step x_t -> x_{t-1} (equation 12 of the DDIM paper)."""
        if self.num_inference_steps == 0:
            raise RuntimeError("call set_timesteps() before step()")
        t = int(timestep)
        prev_t = t - self.step_ratio
        ab_t = self.alpha_bar(t).to(sample.device, sample.dtype)
        ab_prev = self.alpha_bar(prev_t).to(sample.device, sample.dtype)
        if self.config.prediction_type == "epsilon":
            x0 = (sample - torch.sqrt(1 - ab_t) * model_output) / torch.sqrt(ab_t)
            eps = model_output
        else:
            x0 = model_output
            eps = (sample - torch.sqrt(ab_t) * x0) / torch.sqrt(1 - ab_t)
        if self.config.clip_sample:
            r = self.config.clip_sample_range
            # the direction term keeps the model's eps (as diffusers does); only x0 is clipped
            x0 = x0.clamp(-r, r)
        variance = (1 - ab_prev) / (1 - ab_t) * (1 - ab_t / ab_prev)
        std = self.config.eta * torch.sqrt(variance.clamp(min=0))
        direction = torch.sqrt((1 - ab_prev - std**2).clamp(min=0)) * eps
        prev = torch.sqrt(ab_prev) * x0 + direction
        if self.config.eta > 0:
            noise = torch.randn(sample.shape, generator=generator, device=sample.device, dtype=sample.dtype)
            prev = prev + std * noise
        return DDIMStepOutput(prev, x0)

    def add_noise(self, original: torch.Tensor, noise: torch.Tensor, timesteps: torch.Tensor) -> torch.Tensor:
        """Forward process q(x_t | x_0) = sqrt(alpha_bar_t) x_0 + sqrt(1 - alpha_bar_t) eps, per batch item."""
        ab = self.alphas_cumprod.to(original.device)[timesteps].to(original.dtype)
        shape = (-1,) + (1,) * (original.ndim - 1)
        return torch.sqrt(ab).view(shape) * original + torch.sqrt(1 - ab).view(shape) * noise
