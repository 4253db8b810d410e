"""Atomic torch checkpoints: a crash mid-save never leaves a half-written `last.pt` to resume from."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import torch

from grits_lab.errors import StorageError
from grits_lab.io import write_bytes_atomic


def save_checkpoint(path: str | Path, state: dict[str, Any]) -> Path:
    buffer = io.BytesIO()
    torch.save(state, buffer)
    write_bytes_atomic(path, buffer.getvalue())
    return Path(path)


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """Load a checkpoint written by `save_checkpoint`; missing or damaged files raise StorageError."""
    path = Path(path)
    if not path.is_file():
        raise StorageError(f"checkpoint not found: {path}")
    try:
        return torch.load(path, map_location=map_location, weights_only=False)
    except (RuntimeError, EOFError, OSError, ValueError) as exc:
        raise StorageError(f"corrupted or unreadable checkpoint {path}: {exc}") from None
