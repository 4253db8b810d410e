"""Behavior cloning baseline: observation encoder features -> MLP -> the next action chunk (deterministic regression)."""

from grits_lab.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "configuration_bc": ["BCConfig"],
    "modeling_bc": ["BCPolicy"],
})
