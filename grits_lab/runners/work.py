"""Work functions and the per-worker context: what a spec's `work` callable receives inside a worker.

Executors never hard-wire what an episode does: each spec carries its work function (a
module-level function, so it pickles by reference) and the worker calls ``work(spec, context)``.
The runner names no layer above it; the collection and evaluation jobs hand it their functions.
The `WorkerContext` keeps expensive state alive between episodes in the same worker: one
reusable resource such as a simulator (rebuilt only when its key changes, discarded after a
failure) and a generic cache for things such as a policy checkpoint loaded once per worker.
"""

from __future__ import annotations

import os
import socket
import time
import traceback as tb
from typing import Any, Callable

from grits_lab.runners.spec import EpisodeResult, EpisodeSpec


class WorkerContext:
    """State a worker keeps across the episodes it runs (one per actor, or one for the serial executor)."""

    def __init__(self, worker_index: int = 0):
        self.worker_index = worker_index
        self.worker = f"{socket.gethostname()}:{os.getpid()}"
        self._cache: dict[Any, Any] = {}
        self._resource: Any = None
        self._resource_key: str | None = None

    def cached(self, key: Any, factory: Callable[[], Any]) -> Any:
        """`factory()` on first use of `key` in this worker, the stored value afterwards."""
        if key not in self._cache:
            self._cache[key] = factory()
        return self._cache[key]

    def reusable(self, key: str, factory: Callable[[], Any]) -> Any:
        """The worker's one reusable resource (a simulator), built by `factory` on first use and
        again whenever `key` changes (the old one is closed first). A work function that raises
        discards it, so the next spec starts from a fresh one."""
        if self._resource is None or key != self._resource_key:
            self.discard_reusable()
            self._resource = factory()
            self._resource_key = key
        return self._resource

    def discard_reusable(self) -> None:
        """Close and forget the reusable resource (no-op when there is none)."""
        if self._resource is not None:
            try:
                close = getattr(self._resource, "close", None)
                if callable(close):
                    close()
            finally:
                self._resource = None
                self._resource_key = None

    def close(self) -> None:
        self.discard_reusable()
        for value in self._cache.values():
            close = getattr(value, "close", None)
            if callable(close):
                close()
        self._cache.clear()


def execute_spec(spec: EpisodeSpec, context: WorkerContext) -> EpisodeResult:
    """Run one spec; an exception becomes a failed result (with its error) instead of ending the job."""
    start = time.perf_counter()
    try:
        payload = spec.work(spec, context)
    except Exception as exc:  # the job goes on; the failure is recorded with its cause
        # A simulator that raised mid-episode may be in any state: rebuild it for the next spec.
        context.discard_reusable()
        return EpisodeResult(
            episode_id=spec.episode_id,
            ok=False,
            error=f"{type(exc).__name__}: {exc}",
            traceback=tb.format_exc(),
            wall_time_s=time.perf_counter() - start,
            worker=context.worker,
            spec=spec,
        )
    return EpisodeResult(
        episode_id=spec.episode_id,
        ok=True,
        payload=payload,
        wall_time_s=time.perf_counter() - start,
        worker=context.worker,
        spec=spec,
    )


def probe_episode(spec: EpisodeSpec, context: WorkerContext) -> dict[str, Any]:
    """A simulator-free episode for checking executors and measuring their overhead.

    params: ``work_s`` seconds of CPU-bound work (default 0), ``fail`` (raise ValueError) and
    ``sleep_s`` (wall-clock wait, e.g. to kill a worker mid-episode). The payload depends only on
    the seed, so serial and parallel runs must agree exactly.
    """
    import numpy as np

    from grits_lab.seeding import make_rng

    params = spec.params
    if params.get("sleep_s"):
        time.sleep(float(params["sleep_s"]))
    deadline = time.perf_counter() + float(params.get("work_s", 0.0))
    acc = 0.0
    while time.perf_counter() < deadline:
        acc += float(np.sum(np.sqrt(np.arange(2000.0))))
    if params.get("fail"):
        raise ValueError(f"probe episode {spec.episode_id} asked to fail")
    rng = make_rng(spec.seed)
    return {"episode_id": spec.episode_id, "seed": spec.seed, "value": rng.standard_normal(4).tolist()}
