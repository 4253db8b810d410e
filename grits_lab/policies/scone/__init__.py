"""SCONE-style active perception (Tai et al., 2023): probe the food, then scoop conditioned on what the probe felt."""

from grits_lab.policies.scone.controller_scone import ProbeResult, SconeController, adapt_scoop, scoop_prior

__all__ = ["ProbeResult", "SconeController", "adapt_scoop", "scoop_prior"]
