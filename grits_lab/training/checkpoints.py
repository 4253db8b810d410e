"""Atomic torch checkpoints: a crash mid-save never leaves a half-written `last.pt` to resume from, and
loading one never runs code (tensors and plain data only: a results disk may be shared)."""

from __future__ import annotations

import io
import pickle
from pathlib import Path
from typing import Any

import torch

from grits_lab.errors import InputError, StorageError
from grits_lab.io import write_bytes_atomic


def save_checkpoint(path: str | Path, state: dict[str, Any]) -> Path:
    buffer = io.BytesIO()
    torch.save(state, buffer)
    write_bytes_atomic(path, buffer.getvalue())
    return Path(path)


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu", data: bytes | None = None) -> dict[str, Any]:
    """Load a checkpoint written by `save_checkpoint`; missing or damaged files raise StorageError.

    Loads with `weights_only=True`: a file holding any object other than tensors and plain data (a
    pickle whose `__reduce__` would run code) is refused with InputError before anything in it runs.
    data: the file's bytes, read once by the caller (who hashes the same bytes); `path` then only names it.
    """
    path = Path(path)
    if data is None and not path.is_file():
        raise StorageError(f"checkpoint not found: {path}")
    try:
        return torch.load(path if data is None else io.BytesIO(data), map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as exc:
        raise InputError(f"refused checkpoint {path}: {_refusal_reason(exc)}; checkpoints may hold only tensors and plain data") from None
    except (RuntimeError, EOFError, OSError, ValueError) as exc:
        raise StorageError(f"corrupted or unreadable checkpoint {path}: {exc}") from None


def _refusal_reason(exc: pickle.UnpicklingError) -> str:
    """The one line of torch's weights-only refusal that names the offending global, or a short summary."""
    for line in str(exc).splitlines():
        if "unsupported" in line.lower() and "global" in line.lower():
            return line.strip().rstrip(".")
    return "not a torch checkpoint of tensors and plain data"
