"""Behavior cloning baseline: observation encoder features -> MLP -> the next action chunk (deterministic regression)."""

from grits_lab.policies.bc.configuration_bc import BCConfig
from grits_lab.policies.bc.modeling_bc import BCPolicy

__all__ = ["BCConfig", "BCPolicy"]
