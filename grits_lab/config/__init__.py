"""Typed configs loaded from YAML and validated on load."""

from grits_lab.config.typed_yaml import (
    config_changes,
    config_fingerprint,
    config_from_dict,
    config_to_dict,
    load_config,
    load_yaml,
    merge_mappings,
    parse_yaml,
    require,
)

__all__ = [
    "config_changes",
    "config_fingerprint",
    "config_from_dict",
    "config_to_dict",
    "load_config",
    "load_yaml",
    "merge_mappings",
    "parse_yaml",
    "require",
]
