"""Atomic file writes: a reader never sees a half-written file, so interrupted jobs can resume."""

from __future__ import annotations

import contextlib
import errno
import io
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Iterator

from grits_lab.errors import StorageError


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success it replaces `path` in one rename."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
    except OSError as exc:
        raise StorageError(_describe(exc, path)) from None
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        # mkstemp creates 0600; give the file the mode an ordinary write would, so a group that
        # shares the results disk can read reports, records and checkpoints.
        os.chmod(tmp_path, _ordinary_mode(path))
        os.replace(tmp_path, path)
    except OSError as exc:
        raise StorageError(_describe(exc, path)) from None
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())


def write_text_atomic(path: str | Path, text: str) -> None:
    write_bytes_atomic(path, text.encode())


def to_json(obj: Any, indent: int | None = 2, sort_keys: bool = False) -> str:
    """Strict JSON text: NaN and infinities (which json.dumps writes as bare, invalid `NaN`) become null."""
    return json.dumps(_finite_or_none(obj), indent=indent, sort_keys=sort_keys, default=str, allow_nan=False)


def _finite_or_none(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if hasattr(obj, "dtype") and hasattr(obj, "item") and getattr(obj, "ndim", 1) == 0:
        obj = obj.item()  # numpy and torch scalars
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_json_atomic(path: str | Path, obj: Any) -> None:
    write_text_atomic(path, to_json(obj, indent=2, sort_keys=True) + "\n")


def save_npz_atomic(path: str | Path, compress: bool = True, **arrays: Any) -> None:
    """np.savez(_compressed) to `path` atomically."""
    import numpy as np

    buffer = io.BytesIO()
    (np.savez_compressed if compress else np.savez)(buffer, **arrays)
    write_bytes_atomic(path, buffer.getvalue())


def save_parquet_atomic(path: str | Path, frame: Any) -> None:
    """DataFrame.to_parquet to `path` atomically."""
    with atomic_path(path) as tmp:
        frame.to_parquet(tmp, index=False)


def ensure_writable_dir(path: str | Path) -> Path:
    """Create `path` if needed and check that files can be written there, with a clear message."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".write-check."):
            pass
    except OSError as exc:
        raise StorageError(_describe(exc, path)) from None
    return path


def _ordinary_mode(path: Path) -> int:
    """The permission bits `open(path, "w")` would leave: the existing file's, else 0666 less the umask."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        return 0o666 & ~_umask()


def _umask() -> int:
    # Read, not set-and-restore, where the platform allows: setting it briefly to 0 would race with
    # files other threads create in that moment.
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _describe(exc: OSError, path: Path) -> str:
    if exc.errno == errno.ENOSPC:
        return f"no space left on device while writing {path}"
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return f"cannot write to {path}: permission denied or read-only file system"
    return f"cannot write {path}: {exc.strerror or exc}"
