"""CNN-based diffusion policy (Chi et al., 2023) as used by GRITS: 1-D temporal U-Net with FiLM, DDIM."""

from grits_lab.policies.diffusion.configuration_diffusion import (
    DiffusionPolicyConfig,
    ObsEncoderConfig,
    UNetConfig,
)
from grits_lab.policies.diffusion.modeling_diffusion import DiffusionPolicy

__all__ = ["DiffusionPolicy", "DiffusionPolicyConfig", "ObsEncoderConfig", "UNetConfig"]
