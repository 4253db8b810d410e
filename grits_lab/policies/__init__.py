"""Scooping policies, one folder per method (diffusion, bc, rule_based, scone), and the controller protocol they share.

Each method's folder exports its own config and model (`grits_lab.policies.diffusion`, ...);
this package exports what every controller and the training loop agree on
(grits_lab/policies/control.py).
"""

from grits_lab.policies.control import (
    NO_HOOK_COLUMNS,
    Chunk,
    Controller,
    RolloutSettings,
    Rollouts,
    RolloutsFactory,
    ScoopHook,
    ScoopSettings,
    is_still,
    rollout_episodes,
)

__all__ = ["NO_HOOK_COLUMNS", "Chunk", "Controller", "RolloutSettings", "Rollouts", "RolloutsFactory", "ScoopHook", "ScoopSettings",
           "is_still", "rollout_episodes"]
