"""The sampling loop: DDIM denoising with optional cost guidance (GRITS Algorithm 1) and post-hoc adjustment.

Algorithm 1 in the scheduler's symbols (grits_lab/sampling/ddim.py), for each visited timestep t:

    A_{t-1}  = DDIM step from A_t with eps_theta(A_t)              # ordinary denoising
    if t <= s and rho > 0:
        A_{0|t}  = (A_t - sqrt(1 - alpha_bar_t) eps_theta(A_t)) / sqrt(alpha_bar_t)
        A_{t-1} -= rho * grad f(A_{0|t})

`f` is any differentiable `objective(traj_norm (B, horizon, D)) -> (B,)` cost in the policy's
normalized action space (contract 8); the spillage adapter that slices the executed chunk and
calls the predictor lives in grits_lab/spillage. Two gradients are offered:

* "x0" (default, the authors' code): the gradient of f with respect to the detached estimate
  A_{0|t}; one objective backward per guided step, no backprop through the denoiser.
* "xt" (the paper's formula): the gradient with respect to A_t, through the denoiser, which costs
  a second pass of the network's backward per guided step.

With rho = 0, or a threshold s below every visited timestep, no guided branch runs, so the
result is bit-identical to the unguided sample for the same generator.

What rho means (`GuidanceConfig.step`):
* "gradient" (the paper, SPEC "rho = 2.5"): the update is rho * grad f. Its size is rho times
  the predictor's gradient norm, which depends on the predictor (its training, its saturation:
  the gradient of a probability near 0 or 1 vanishes) and on the action normalizer, so a rho
  tuned for one predictor means nothing for another.
* "normalized": the update is rho * grad f / ||grad f|| (per sample, over the horizon): rho is
  the distance moved per guided step in the policy's normalized action space, the same for every
  predictor; the predictor only gives the direction.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Literal, Protocol

import torch

from grits_lab.config import require
from grits_lab.sampling.ddim import DDIMConfig, DDIMScheduler

Denoiser = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]
"""`denoise(sample (B, H, D), timesteps (B,) long) -> model output (B, H, D)`, conditioning baked in."""

Objective = Callable[[torch.Tensor], torch.Tensor]
"""`objective(traj_norm (B, H, D)) -> (B,)` differentiable cost, e.g. P(spill) of the executed chunk."""


@dataclass
class GuidanceConfig:
    """GRITS guidance (Algorithm 1): the sampler's settings and the `guidance:` block of an evaluation config.

    Paper (SPEC): rho = 2.5, s = 30 on the 100-step training scale, detached A_{0|t} gradient.
    The sweep (grits_lab/tune) overrides rho and s.
    """

    rho: float = 2.5
    s: int = 30  # steps with t <= s are guided (t on the training scale); -1 guides no step
    gradient: Literal["x0", "xt"] = "x0"  # w.r.t. detached A_{0|t} (authors' code) or A_t (paper)
    grad_clip: float | None = None  # clamp each gradient entry to [-c, c] (per axis) before scaling (the authors' code clips)
    clip_estimate: bool = False  # clip A_{0|t} to the action range before evaluating f
    diagnostics: bool = True  # also evaluate f after the update (one more objective call per step)
    # gradient: update = rho * grad f (the paper); normalized: rho * grad f / ||grad f||, so rho is
    # the step length in normalized action units whatever the predictor (module docstring).
    step: Literal["gradient", "normalized"] = "gradient"
    # Per plan, also denoise the same initial noise without guidance and evaluate f on both
    # finished samples (one more unguided denoising pass per plan): what guidance changed.
    compare_unguided: bool = True

    def __post_init__(self) -> None:
        require(self.rho >= 0, "guidance.rho", self.rho, "non-negative")
        require(self.s >= -1, "guidance.s", self.s, "at least -1 (-1 guides no step)")
        require(self.grad_clip is None or self.grad_clip > 0, "guidance.grad_clip", self.grad_clip, "positive or null")
        require(self.step in ("gradient", "normalized"), "guidance.step", self.step, "gradient or normalized")


@dataclass
class PostHocConfig:
    """"Diffusion Policy (Post.)": gradient steps on the finished trajectory (authors' code: 6)."""

    rho: float = 2.5
    n_steps: int = 6
    grad_clip: float | None = None

    def __post_init__(self) -> None:
        require(self.rho >= 0, "rho", self.rho, "non-negative")
        require(self.n_steps >= 0, "n_steps", self.n_steps, "a non-negative integer")
        require(self.grad_clip is None or self.grad_clip > 0, "grad_clip", self.grad_clip, "positive or null")


@dataclass
class StepDiagnostics:
    """What one guidance (or post-hoc) update did, per batch item (tensors of shape (B,))."""

    timestep: int  # training-scale t, or -1 - i for the i-th post-hoc step
    cost_before: torch.Tensor  # f(A_{0|t})
    cost_after: torch.Tensor | None  # f(A_{0|t} - rho * g): the estimate moved by the same update
    grad_norm: torch.Tensor  # ||g|| before clipping
    displacement: torch.Tensor  # ||rho * g|| after clipping: how far the trajectory moved


@dataclass
class SampleResult:
    sample: torch.Tensor  # A_0, (B, H, D) in normalized action space
    steps: list[StepDiagnostics] = field(default_factory=list)
    # With compare_unguided (or post-hoc): the unguided A_0 from the same noise, and f of both samples.
    unguided: torch.Tensor | None = None
    cost_unguided: torch.Tensor | None = None  # (B,) f(unguided A_0)
    cost_final: torch.Tensor | None = None  # (B,) f(A_0)

    def summary(self) -> dict[str, Any]:
        """Plain numbers for logs and records: guided step count and mean diagnostics."""
        out: dict[str, Any] = {"guided_steps": len(self.steps)}
        if self.cost_unguided is not None and self.cost_final is not None:
            out["p_spill_unguided"] = float(self.cost_unguided.mean())
            out["p_spill_guided"] = float(self.cost_final.mean())
        if self.steps:
            out["guided_timesteps"] = [s.timestep for s in self.steps]
            out["cost_first"] = float(self.steps[0].cost_before.mean())
            last = self.steps[-1]
            out["cost_last"] = float((last.cost_after if last.cost_after is not None else last.cost_before).mean())
            out["grad_norm_mean"] = float(torch.stack([s.grad_norm for s in self.steps]).mean())
            out["displacement_total"] = float(torch.stack([s.displacement for s in self.steps]).sum(0).mean())
        return out


class Sampler(Protocol):
    """What a policy needs from a sampler; guidance plugs in by passing a different one."""

    def sample(
        self,
        denoise: Denoiser,
        shape: tuple[int, ...],
        *,
        generator: torch.Generator | None = None,
        objective: Objective | None = None,
        device: torch.device | str = "cpu",
    ) -> SampleResult: ...


def _per_item_norm(x: torch.Tensor) -> torch.Tensor:
    return x.flatten(1).norm(dim=1)


def _objective_grad(objective: Objective, at: torch.Tensor, wrt: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(cost (B,), d sum(cost) / d wrt); `at` must be a function of `wrt` in the current graph."""
    cost = objective(at)
    if cost.shape != (at.shape[0],):
        raise ValueError(f"objective must return shape ({at.shape[0]},); got {tuple(cost.shape)}")
    (grad,) = torch.autograd.grad(cost.sum(), wrt)
    return cost.detach(), grad


def _clip(grad: torch.Tensor, clip: float | None) -> torch.Tensor:
    return grad if clip is None else grad.clamp(-clip, clip)


def _step_direction(grad: torch.Tensor, clip: float | None, step: str) -> torch.Tensor:
    """The direction rho multiplies: the (clipped) gradient, or its unit vector per sample."""
    d = _clip(grad, clip)
    if step == "normalized":
        d = d / _per_item_norm(d).clamp_min(1e-12).view(-1, *([1] * (d.ndim - 1)))
    return d


def _final_costs(objective: Objective, unguided: torch.Tensor, guided: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    with torch.no_grad():
        return objective(unguided).detach(), objective(guided).detach()


class DDIMSampler:
    """DDIM sampling with optional Algorithm-1 guidance; `guidance=None` is the plain policy."""

    def __init__(self, scheduler: DDIMConfig | DDIMScheduler | None = None, guidance: GuidanceConfig | None = None) -> None:
        self.scheduler = scheduler if isinstance(scheduler, DDIMScheduler) else DDIMScheduler(scheduler)
        self.guidance = guidance

    def guided_timesteps(self) -> list[int]:
        """The visited timesteps at which guidance acts (empty when rho = 0)."""
        g = self.guidance
        if g is None or g.rho == 0:
            return []
        return [int(t) for t in self.scheduler.timesteps if int(t) <= g.s]

    def sample(
        self,
        denoise: Denoiser,
        shape: tuple[int, ...],
        *,
        generator: torch.Generator | None = None,
        objective: Objective | None = None,
        device: torch.device | str = "cpu",
    ) -> SampleResult:
        """Draw A_T ~ N(0, I) from `generator` and denoise it; guided when guidance and objective are set."""
        sched = self.scheduler
        g = self.guidance
        guided = set(self.guided_timesteps()) if objective is not None else set()
        if g is not None and g.rho > 0 and objective is None and self.guided_timesteps():
            raise ValueError("guided sampling needs an objective")
        twin = None
        if guided and g is not None and g.compare_unguided:
            twin = torch.Generator(device=device)
            if generator is not None:
                twin.set_state(generator.get_state())
            else:
                twin.seed()
                generator = torch.Generator(device=device)
                generator.set_state(twin.get_state())
        x = torch.randn(shape, generator=generator, device=device, dtype=torch.float32)
        batch = torch.ones(shape[0], dtype=torch.long, device=device)
        steps: list[StepDiagnostics] = []
        for t_tensor in sched.timesteps:
            t = int(t_tensor)
            if t in guided and g is not None and g.gradient == "xt":
                x_in = x.detach().requires_grad_(True)
                with torch.enable_grad():
                    eps = denoise(x_in, batch * t)
                    x0_est = sched.predict_original(eps, t, x_in)
                    if g.clip_estimate:
                        x0_est = x0_est.clamp(-sched.config.clip_sample_range, sched.config.clip_sample_range)
                    cost, grad = _objective_grad(objective, x0_est, x_in)  # type: ignore[arg-type]
                eps = eps.detach()
            else:
                with torch.no_grad():
                    eps = denoise(x, batch * t)
            with torch.no_grad():
                x_prev = sched.step(eps, t, x, generator=generator).prev_sample
            if t in guided and g is not None:
                if g.gradient == "x0":
                    with torch.no_grad():
                        x0_est = sched.predict_original(eps, t, x)
                        if g.clip_estimate:
                            x0_est = x0_est.clamp(-sched.config.clip_sample_range, sched.config.clip_sample_range)
                    x0_leaf = x0_est.detach().requires_grad_(True)
                    with torch.enable_grad():
                        cost, grad = _objective_grad(objective, x0_leaf, x0_leaf)  # type: ignore[arg-type]
                update = g.rho * _step_direction(grad, g.grad_clip, g.step)
                x_prev = x_prev - update
                cost_after = None
                if g.diagnostics:
                    with torch.no_grad():
                        cost_after = objective(x0_est.detach() - update).detach()  # type: ignore[misc]
                steps.append(StepDiagnostics(t, cost, cost_after, _per_item_norm(grad), _per_item_norm(update)))
            x = x_prev.detach()
        result = SampleResult(x, steps)
        if twin is not None:
            result.unguided = DDIMSampler(sched).sample(denoise, shape, generator=twin, device=device).sample
            result.cost_unguided, result.cost_final = _final_costs(objective, result.unguided, x)  # type: ignore[arg-type]
        return result


def posthoc_adjust(
    trajectory: torch.Tensor, objective: Objective, config: PostHocConfig | None = None
) -> SampleResult:
    """Move a finished trajectory (B, H, D) by `n_steps` gradient steps A <- A - rho * grad f(A)."""
    config = config or PostHocConfig()
    x = trajectory.detach().clone()
    steps: list[StepDiagnostics] = []
    if config.rho == 0:
        return SampleResult(x, steps)
    for i in range(config.n_steps):
        leaf = x.requires_grad_(True)
        with torch.enable_grad():
            cost, grad = _objective_grad(objective, leaf, leaf)
        update = config.rho * _clip(grad, config.grad_clip)
        x = (leaf - update).detach()
        steps.append(StepDiagnostics(-1 - i, cost, None, _per_item_norm(grad), _per_item_norm(update)))
    if steps:
        with torch.no_grad():
            steps[-1].cost_after = objective(x).detach()
    return SampleResult(x, steps)


class PostHocSampler:
    """Unguided DDIM, then `posthoc_adjust` with the objective: the "Diffusion Policy (Post.)" baseline."""

    def __init__(self, scheduler: DDIMConfig | DDIMScheduler | None = None, posthoc: PostHocConfig | None = None) -> None:
        self.base = DDIMSampler(scheduler)
        self.posthoc = posthoc or PostHocConfig()
        self.scheduler = self.base.scheduler

    def sample(
        self,
        denoise: Denoiser,
        shape: tuple[int, ...],
        *,
        generator: torch.Generator | None = None,
        objective: Objective | None = None,
        device: torch.device | str = "cpu",
    ) -> SampleResult:
        result = self.base.sample(denoise, shape, generator=generator, device=device)
        if objective is None:
            if self.posthoc.rho > 0 and self.posthoc.n_steps > 0:
                raise ValueError("post-hoc adjustment needs an objective")
            return result
        adjusted = posthoc_adjust(result.sample, objective, self.posthoc)
        adjusted.unguided = result.sample
        adjusted.cost_unguided, adjusted.cost_final = _final_costs(objective, result.sample, adjusted.sample)
        return adjusted
