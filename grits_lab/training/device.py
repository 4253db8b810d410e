"""Device choice (`auto` = CUDA when present) and CPU thread limits for a shared machine."""

from __future__ import annotations

import torch

from grits_lab.errors import ConfigError


def resolve_device(name: str) -> torch.device:
    """"auto" -> cuda if available else cpu; an explicit "cuda" without a GPU is a config error."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"`device` is {name!r} but no CUDA device is available; use `auto` or `cpu`")
    try:
        return torch.device(name)
    except RuntimeError:
        raise ConfigError(f"`device` must be auto, cpu or cuda[:N]. Got {name!r}.") from None


def set_torch_threads(n: int) -> None:
    """Limit intra-op threads (0 keeps torch's default); the team shares a 2-core machine."""
    if n > 0:
        torch.set_num_threads(n)
