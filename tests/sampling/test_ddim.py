"""DDIM scheduler: schedule, timesteps and the whole loop against an independent float64 reference."""

import math

import numpy as np
import pytest
import torch

from grits_lab.errors import ConfigError
from grits_lab.sampling import DDIMConfig, DDIMSampler, DDIMScheduler


def _closed_form_alpha_bar(t, T=100):
    # squared cosine: alpha_bar(t) = f(t + 1) / f(0), f(u) = cos^2((u / T + 0.008) / 1.008 * pi / 2)
    f = lambda u: math.cos((u / T + 0.008) / 1.008 * math.pi / 2) ** 2
    return f(t + 1) / f(0)


def test_squared_cosine_alpha_bar_matches_closed_form():
    sched = DDIMScheduler(DDIMConfig())
    for t in [0, 1, 10, 30, 50, 90, 98]:
        assert sched.alphas_cumprod[t].item() == pytest.approx(_closed_form_alpha_bar(t), rel=1e-5)
    assert float(sched.betas[-1]) == pytest.approx(0.999)  # capped


def test_leading_timesteps_for_100_over_16():
    sched = DDIMScheduler(DDIMConfig(num_train_timesteps=100, num_inference_steps=16))
    assert sched.timesteps.tolist() == list(range(90, -1, -6))
    sched.set_timesteps(10)
    assert sched.timesteps.tolist() == list(range(90, -1, -10))


def _reference_loop(x, model, T, n, clip):
    """Independent DDIM (eta = 0) in float64 numpy from the closed-form schedule."""
    ratio = T // n
    for t in range(ratio * (n - 1), -1, -ratio):
        ab = _closed_form_alpha_bar(t, T)
        ab_prev = _closed_form_alpha_bar(t - ratio, T) if t - ratio >= 0 else 1.0
        eps = model(x, t)
        x0 = (x - math.sqrt(1 - ab) * eps) / math.sqrt(ab)
        if clip:
            x0 = np.clip(x0, -1, 1)
        x = math.sqrt(ab_prev) * x0 + math.sqrt(1 - ab_prev) * eps
    return x


@pytest.mark.parametrize("clip", [False, True])
def test_full_loop_with_dummy_model_matches_reference(clip):
    def np_model(x, t):
        return 0.3 * np.tanh(x) + 0.002 * t - 0.05

    def torch_model(x, t):
        return 0.3 * torch.tanh(x) + 0.002 * t.view(-1, 1, 1).float() - 0.05

    gen = torch.Generator().manual_seed(7)
    sampler = DDIMSampler(DDIMConfig(clip_sample=clip))
    result = sampler.sample(torch_model, (3, 16, 9), generator=gen)
    x_T = torch.randn((3, 16, 9), generator=torch.Generator().manual_seed(7)).double().numpy()
    expected = _reference_loop(x_T, np_model, 100, 16, clip)
    np.testing.assert_allclose(result.sample.numpy(), expected, atol=2e-5)
    assert result.steps == []


def test_linear_model_known_value():
    # eps = 0: x0 = x_T / sqrt(alpha_bar_90) at the first step, and every later step keeps x0
    # (prev = sqrt(ab_prev) x0, whose estimate is again x0), so A_0 = x_T / sqrt(alpha_bar_90).
    x_T = torch.full((1, 2, 3), 0.1)
    sched = DDIMScheduler(DDIMConfig(clip_sample=False))
    x = x_T
    for t in sched.timesteps:
        x = sched.step(torch.zeros_like(x), t, x).prev_sample
    assert x[0, 0, 0].item() == pytest.approx(0.1 / math.sqrt(_closed_form_alpha_bar(90)), rel=1e-5)


def test_true_noise_recovers_original_at_the_last_step():
    sched = DDIMScheduler()
    x0 = torch.rand(4, 16, 9) * 2 - 1
    noise = torch.randn(4, 16, 9, generator=torch.Generator().manual_seed(0))
    t = torch.zeros(4, dtype=torch.long)
    noisy = sched.add_noise(x0, noise, t)
    out = sched.step(noise, 0, noisy)
    torch.testing.assert_close(out.prev_sample, x0, atol=1e-5, rtol=0)


def test_eta_zero_ignores_the_generator_after_the_initial_noise():
    sched = DDIMScheduler()
    x = torch.randn(2, 4, 9)
    eps = torch.randn(2, 4, 9)
    a = sched.step(eps, 48, x, generator=torch.Generator().manual_seed(1)).prev_sample
    b = sched.step(eps, 48, x, generator=torch.Generator().manual_seed(2)).prev_sample
    assert torch.equal(a, b)


def test_bad_config_names_the_key():
    from grits_lab.config import config_from_dict

    with pytest.raises(ConfigError, match="num_inference_steps"):
        config_from_dict(DDIMConfig, {"num_inference_steps": 0})
    with pytest.raises(ConfigError, match="beta_schedule"):
        config_from_dict(DDIMConfig, {"beta_schedule": "cosine"})
