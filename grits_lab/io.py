"""Atomic file writes (a reader never sees a half-written file, so interrupted jobs can resume) and
one writer per output directory (two jobs writing one directory would lose each other's records)."""

from __future__ import annotations

import contextlib
import errno
import io
import json
import math
import os
import socket
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Iterator

from grits_lab.errors import StorageError


@contextlib.contextmanager
def atomic_path(path: str | Path, mode: int | None = None) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success it replaces `path` in one rename.

    The file gets `mode`, or with None the mode an ordinary write would give it."""
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
        os.chmod(tmp_path, _ordinary_mode(path) if mode is None else mode)
        os.replace(tmp_path, path)
    except OSError as exc:
        raise StorageError(_describe(exc, path)) from None
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_bytes_atomic(path: str | Path, data: bytes, mode: int | None = None) -> None:
    with atomic_path(path, mode) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())


def write_text_atomic(path: str | Path, text: str, mode: int | None = None) -> None:
    write_bytes_atomic(path, text.encode(), mode)


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


def check_writable_dir(path: str | Path, named: str | Path | None = None) -> Path:
    """Before the work: StorageError naming `path` unless files can be written there, tried in the
    directory itself or, where it does not exist yet, in its nearest existing parent (a read-only
    file system, no permission, a file where a directory belongs). Creates nothing. `named`: what
    the message names instead of `path` (a file to be written there)."""
    path = Path(path)
    shown = path if named is None else named
    existing = path.absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise StorageError(f"cannot write {shown}: {existing} is not a directory")
    try:
        with tempfile.NamedTemporaryFile(dir=existing, prefix=".write-check."):
            pass
    except OSError as exc:
        raise StorageError(_describe(exc, Path(shown))) from None
    return path


def check_writable_file(path: str | Path) -> Path:
    """Before the work: StorageError naming `path` unless a file can be written there
    (`check_writable_dir` of its folder; a directory at `path` itself is refused too)."""
    path = Path(path)
    if path.is_dir():
        raise StorageError(f"cannot write {path}: it is a directory")
    check_writable_dir(path.parent, named=path)
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


LOCK_FILE = ".grits-lab.lock"


@contextlib.contextmanager
def exclusive_directory(path: str | Path, command: str) -> Iterator[Path]:
    """Hold `path/.grits-lab.lock` while `command` writes into `path`; a second writer is refused.

    The lock is an advisory `flock` on the file (the kernel releases it when its holder dies, so a
    lock left by a killed process is taken over, with one line saying so), and the file names its
    holder (pid, host, command, start time) for the refusal: StorageError, one line. A file system
    without `flock` falls back to the named holder: taken over when it is a dead process of this host.
    """
    import fcntl

    path = Path(path)
    lock_path = path / LOCK_FILE
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as exc:
        raise StorageError(_describe(exc, lock_path)) from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            flocked = True
        except BlockingIOError:
            raise StorageError(f"{path} is being written by {_holder_text(_read_holder(fd))}; "
                               f"one writer per directory: wait for it to finish or choose another output directory") from None
        except OSError:  # no flock here (some network file systems): trust the named holder
            flocked = False
        previous = _read_holder(fd)
        if previous and not (flocked or _is_dead_here(previous)):
            raise StorageError(f"{path} is being written by {_holder_text(previous)}; "
                               f"one writer per directory: wait for it to finish, or remove {lock_path} if it is not running")
        if previous:
            print(f"grits-lab: taking over {lock_path} from {_holder_text(previous)}, which ended without releasing it", file=sys.stderr)
        holder = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
                  "started": time.strftime("%Y-%m-%d %H:%M:%S %z")}
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(holder) + "\n").encode(), 0)
        os.fsync(fd)
        try:
            yield path
        finally:
            os.ftruncate(fd, 0)  # an empty file is a released lock; unlinking it would race a waiting writer
    finally:
        os.close(fd)  # releases the flock


def _read_holder(fd: int) -> dict[str, Any]:
    try:
        data = json.loads(os.pread(fd, 4096, 0).decode() or "{}")
    except (ValueError, OSError):
        return {}
    return data if isinstance(data, dict) else {}


def _holder_text(holder: dict[str, Any]) -> str:
    if not holder:
        return "another process"
    return f"`grits-lab {holder.get('command', '?')}` (pid {holder.get('pid', '?')} on {holder.get('host', '?')}, since {holder.get('started', '?')})"


def _is_dead_here(holder: dict[str, Any]) -> bool:
    """True when the holder is a process of this host that no longer runs."""
    try:
        return holder.get("host") == socket.gethostname() and not pid_alive(int(holder.get("pid", -1)))
    except (TypeError, ValueError):
        return False


def pid_alive(pid: int) -> bool:
    """Whether process `pid` of this host still runs (one of another user counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # PermissionError: it exists; EINVAL and the like: do not call it gone
        return True
    return True
