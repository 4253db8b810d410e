"""Guided sampling (Algorithm 1) and post-hoc adjustment: exactness, direction, the threshold s."""

import math

import pytest
import torch

from grits_lab.sampling import (
    DDIMConfig,
    DDIMSampler,
    GuidanceConfig,
    PostHocConfig,
    PostHocSampler,
    posthoc_adjust,
)

SHAPE = (4, 16, 9)


def dummy_denoiser(x, t):
    # deterministic, nonlinear, timestep-dependent: enough to make a non-trivial trajectory
    return 0.4 * torch.tanh(x) + 0.001 * t.view(-1, 1, 1).float()


def x_coordinate_cost(traj):
    """Mean of the x coordinate: guidance should push it down."""
    return traj[..., 0].mean(dim=1)


class CountingObjective:
    def __init__(self, fn):
        self.fn, self.calls = fn, 0

    def __call__(self, traj):
        self.calls += 1
        return self.fn(traj)


def _sample(guidance, objective=x_coordinate_cost, seed=3, config=None):
    sampler = DDIMSampler(config or DDIMConfig(), guidance)
    return sampler.sample(dummy_denoiser, SHAPE, generator=torch.Generator().manual_seed(seed), objective=objective)


@pytest.mark.parametrize("gradient", ["x0", "xt"])
def test_rho_zero_or_s_below_every_step_is_exactly_unguided(gradient):
    plain = _sample(None, objective=None).sample
    assert torch.equal(_sample(GuidanceConfig(rho=0.0, gradient=gradient)).sample, plain)
    assert torch.equal(_sample(GuidanceConfig(rho=2.5, s=-1, gradient=gradient)).sample, plain)


@pytest.mark.parametrize("gradient", ["x0", "xt"])
def test_guidance_moves_the_sample_downhill(gradient):
    plain = _sample(None, objective=None).sample
    guided = _sample(GuidanceConfig(rho=0.5, s=100, gradient=gradient, clip_estimate=False))
    assert (x_coordinate_cost(guided.sample) < x_coordinate_cost(plain) - 0.05).all()
    # other axes are not pushed by an x-only cost as hard as x is
    shift = (plain - guided.sample).mean(dim=(0, 1))
    assert shift[0] > 0 and shift[0] > shift[1:].abs().max()
    for step in guided.steps:
        assert step.cost_after is not None and (step.cost_after < step.cost_before).all()
        assert step.grad_norm.shape == (SHAPE[0],) and (step.displacement > 0).all()


def test_s_selects_the_last_steps_on_the_training_scale():
    counter = CountingObjective(x_coordinate_cost)
    result = _sample(GuidanceConfig(rho=1.0, s=30, diagnostics=False, compare_unguided=False), objective=counter)
    assert [s.timestep for s in result.steps] == [30, 24, 18, 12, 6, 0]
    assert counter.calls == 6
    assert DDIMSampler(DDIMConfig(), GuidanceConfig(s=29)).guided_timesteps() == [24, 18, 12, 6, 0]
    assert len(DDIMSampler(DDIMConfig(), GuidanceConfig(s=100)).guided_timesteps()) == 16
    # guiding only late steps leaves earlier steps untouched: the trajectories agree before t = 30
    early = _sample(GuidanceConfig(rho=1.0, s=30))
    assert not torch.equal(early.sample, _sample(None, objective=None).sample)


def test_xt_gradient_is_the_x0_gradient_through_a_linear_denoiser():
    # eps = c x  =>  A_{0|t} = k A_t with k = (1 - sqrt(1 - ab) c) / sqrt(ab), so grad_xt = k grad_x0
    c = 0.5
    sampler_cfg = DDIMConfig(clip_sample=False)
    denoise = lambda x, t: c * x
    results = {}
    for mode in ("x0", "xt"):
        sampler = DDIMSampler(sampler_cfg, GuidanceConfig(rho=1.0, s=90, gradient=mode))
        results[mode] = sampler.sample(denoise, (2, 4, 9), generator=torch.Generator().manual_seed(0), objective=x_coordinate_cost)
    ab = float(sampler.scheduler.alphas_cumprod[90])
    k = (1 - math.sqrt(1 - ab) * c) / math.sqrt(ab)
    first_x0, first_xt = results["x0"].steps[0], results["xt"].steps[0]
    torch.testing.assert_close(first_xt.grad_norm, abs(k) * first_x0.grad_norm)


def test_per_axis_clip_bounds_every_update_entry():
    big = lambda traj: 100.0 * traj[..., 0].mean(dim=1)
    result = _sample(GuidanceConfig(rho=2.0, s=100, grad_clip=0.01), objective=big)
    n_entries = SHAPE[1] * SHAPE[2]
    for step in result.steps:
        assert (step.displacement <= 2.0 * 0.01 * math.sqrt(n_entries) + 1e-6).all()
        assert (step.grad_norm > 1.0).all()  # the raw gradient was large; the clip did the work


def test_guided_sampling_needs_an_objective():
    with pytest.raises(ValueError, match="objective"):
        DDIMSampler(DDIMConfig(), GuidanceConfig()).sample(dummy_denoiser, SHAPE)


def test_posthoc_adjustment_descends_and_rho_zero_is_identity():
    traj = torch.randn(3, 16, 9, generator=torch.Generator().manual_seed(5))
    target = torch.zeros_like(traj)
    quadratic = lambda a: ((a - target) ** 2).sum(dim=(1, 2))
    out = posthoc_adjust(traj, quadratic, PostHocConfig(rho=0.1, n_steps=6))
    assert len(out.steps) == 6
    costs = [s.cost_before for s in out.steps] + [out.steps[-1].cost_after]
    for before, after in zip(costs, costs[1:]):
        assert (after < before).all()
    # gradient descent on |a|^2 with step rho: a_n = (1 - 2 rho)^n a_0
    torch.testing.assert_close(out.sample, traj * 0.8**6)
    assert torch.equal(posthoc_adjust(traj, quadratic, PostHocConfig(rho=0.0)).sample, traj)


def test_posthoc_sampler_starts_from_the_unguided_sample():
    plain = _sample(None, objective=None).sample
    sampler = PostHocSampler(DDIMConfig(), PostHocConfig(rho=0.0))
    same = sampler.sample(dummy_denoiser, SHAPE, generator=torch.Generator().manual_seed(3), objective=x_coordinate_cost)
    assert torch.equal(same.sample, plain)
    sampler = PostHocSampler(DDIMConfig(), PostHocConfig(rho=0.5, n_steps=6))
    moved = sampler.sample(dummy_denoiser, SHAPE, generator=torch.Generator().manual_seed(3), objective=x_coordinate_cost)
    assert (x_coordinate_cost(moved.sample) < x_coordinate_cost(plain)).all()


def test_normalized_step_moves_rho_per_guided_step_whatever_the_gradient_scale():
    # The same cost scaled by 1000 has a 1000x gradient: the paper's step grows with it, the
    # normalized step does not.
    for scale in (1.0, 1000.0):
        cost = lambda traj, k=scale: k * x_coordinate_cost(traj)  # noqa: E731
        result = _sample(GuidanceConfig(rho=0.2, s=100, step="normalized"), objective=cost)
        assert all(torch.allclose(s.displacement, torch.full((SHAPE[0],), 0.2)) for s in result.steps)
    paper = [_sample(GuidanceConfig(rho=0.2, s=100), objective=lambda t, k=k: k * x_coordinate_cost(t)) for k in (1.0, 10.0)]
    assert (paper[1].steps[0].displacement > 5 * paper[0].steps[0].displacement).all()


def test_compare_unguided_gives_the_plain_sample_from_the_same_noise_and_both_costs():
    plain = _sample(None, objective=None).sample
    result = _sample(GuidanceConfig(rho=0.5, s=100, compare_unguided=True))
    assert torch.equal(result.unguided, plain)
    assert torch.allclose(result.cost_unguided, x_coordinate_cost(plain)) and torch.allclose(result.cost_final, x_coordinate_cost(result.sample))
    assert (result.cost_final < result.cost_unguided).all()
    summary = result.summary()
    assert summary["p_spill_guided"] < summary["p_spill_unguided"]
    # Without the comparison the guided sample is the same; only the extra pass is skipped.
    alone = _sample(GuidanceConfig(rho=0.5, s=100, compare_unguided=False))
    assert torch.equal(alone.sample, result.sample) and alone.unguided is None


def test_posthoc_sampler_reports_the_unguided_sample_and_both_costs():
    sampler = PostHocSampler(DDIMConfig(), PostHocConfig(rho=0.5, n_steps=3))
    result = sampler.sample(dummy_denoiser, SHAPE, generator=torch.Generator().manual_seed(3), objective=x_coordinate_cost)
    assert torch.equal(result.unguided, _sample(None, objective=None).sample)
    assert (result.cost_final < result.cost_unguided).all()
