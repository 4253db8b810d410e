"""Fixtures shared across test packages."""

from __future__ import annotations

import errno
import os
import signal

import pytest


@pytest.fixture
def kill_a_worker_mid_episode(monkeypatch):
    """SIGKILL one Ray worker at the first poll that finds episodes running: a real lost process.

    Patches `RayExecutor.poll`, so it reaches executors that jobs build themselves (collect,
    evaluate). Yields the list of killed pids (one entry once the kill happened).
    """
    from grits_lab.runners.ray_executor import RayExecutor

    killed: list[int] = []
    original = RayExecutor.poll

    def poll(self, timeout=None):
        if not killed and self._in_flight:
            pid = self.worker_pids()[0]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
        return original(self, timeout)

    monkeypatch.setattr(RayExecutor, "poll", poll)
    yield killed


@pytest.fixture
def full_disk(monkeypatch):
    """The file system runs out of space: data reaches the page cache, fsync reports ENOSPC (as on ext4)."""

    def fsync(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", fsync)


class _RunsCode:
    """Unpickling this calls `touch marker`: a checkpoint entry that runs a shell command."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


@pytest.fixture
def plant_pickle(tmp_path):
    """plant(good, planted) re-saves checkpoint `good` as `planted` with one extra entry whose
    `__reduce__` creates a marker file; returns the marker's path (it must never exist)."""
    import torch

    def plant(good, planted):
        marker = tmp_path / f"ran-{os.path.basename(str(planted))}"
        state = torch.load(good, weights_only=True)
        state["extra"] = _RunsCode(marker)
        torch.save(state, planted)
        return marker

    return plant


@pytest.fixture
def hold_directory():
    """hold(path, command) starts another process that holds `path`'s writer lock as `command`
    (grits_lab.io.exclusive_directory) and returns it once the lock is held; it is killed at teardown."""
    import subprocess
    import sys

    code = ("import sys, time; from grits_lab.io import exclusive_directory\n"
            "with exclusive_directory(sys.argv[1], sys.argv[2]):\n    print('held', flush=True); time.sleep(600)\n")
    procs = []

    def hold(path, command):
        proc = subprocess.Popen([sys.executable, "-c", code, str(path), command], stdout=subprocess.PIPE, text=True)
        procs.append(proc)
        assert proc.stdout.readline().strip() == "held"
        return proc

    yield hold
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
