"""Diffusion sampling, independent of any network: DDIM, GRITS guidance, post-hoc adjustment."""

from grits_lab.sampling.ddim import DDIMConfig, DDIMScheduler, DDIMStepOutput, squared_cosine_betas
from grits_lab.sampling.guidance import (
    DDIMSampler,
    Denoiser,
    GuidanceConfig,
    Objective,
    PostHocConfig,
    PostHocSampler,
    SampleResult,
    Sampler,
    StepDiagnostics,
    posthoc_adjust,
)

__all__ = [
    "DDIMConfig",
    "DDIMSampler",
    "DDIMScheduler",
    "DDIMStepOutput",
    "Denoiser",
    "GuidanceConfig",
    "Objective",
    "PostHocConfig",
    "PostHocSampler",
    "SampleResult",
    "Sampler",
    "StepDiagnostics",
    "posthoc_adjust",
    "squared_cosine_betas",
]
