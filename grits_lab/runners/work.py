"""Work functions and the per-worker context: how a spec's `work` name becomes a call inside a worker.

Executors never hard-wire what an episode does. A spec names a registered kind (`WORK_KINDS`,
extendable with `register_work`) or an importable ``module:function`` path; the worker imports the
function and calls ``fn(spec, context)``. The `WorkerContext` keeps expensive state alive between
episodes in the same worker: one simulator (rebuilt only when its config changes) and a generic
cache for things such as a policy checkpoint loaded once per worker.
"""

from __future__ import annotations

import importlib
import os
import socket
import time
import traceback as tb
from typing import Any, Callable

from grits_lab.errors import InputError
from grits_lab.runners.spec import EpisodeResult, EpisodeSpec

WorkFn = Callable[[EpisodeSpec, "WorkerContext"], Any]

# kind -> "module:function". Paths (not functions) so that a worker resolves them by import and a
# registration made in the driver travels with the spec (executors resolve names before sending).
WORK_KINDS: dict[str, str] = {
    "probe": "grits_lab.runners.work:probe_episode",
    "demo": "grits_lab.data.demos:demo_episode",
    "spillage": "grits_lab.data.spillage:spillage_trial",
}


def register_work(kind: str, path: str) -> None:
    """Register `kind` as a name for the work function at ``"module:function"``."""
    if ":" not in path:
        raise InputError(f"work path must look like 'package.module:function'. Got {path!r}.")
    WORK_KINDS[kind] = path


def resolve_work_path(work: str) -> str:
    """The ``module:function`` path a spec's `work` refers to (a registered kind or a path)."""
    if work in WORK_KINDS:
        return WORK_KINDS[work]
    if ":" in work:
        return work
    known = ", ".join(sorted(WORK_KINDS))
    raise InputError(f"unknown work kind {work!r}; registered kinds: {known}; or give 'module:function'")


def import_work(path: str) -> WorkFn:
    module_name, _, attr = resolve_work_path(path).partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise InputError(f"cannot import work module {module_name!r}: {exc}") from None
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise InputError(f"work function {attr!r} not found in {module_name}")
    return fn


class WorkerContext:
    """State a worker keeps across the episodes it runs (one per actor, or one for the serial executor)."""

    def __init__(self, worker_index: int = 0):
        self.worker_index = worker_index
        self.worker = f"{socket.gethostname()}:{os.getpid()}"
        self._cache: dict[Any, Any] = {}
        self._env: Any = None
        self._env_key: str | None = None
        self._functions: dict[str, WorkFn] = {}

    def cached(self, key: Any, factory: Callable[[], Any]) -> Any:
        """`factory()` on first use of `key` in this worker, the stored value afterwards."""
        if key not in self._cache:
            self._cache[key] = factory()
        return self._cache[key]

    def env(self, sim_config: Any) -> Any:
        """This worker's one ScoopEnv, built here (never pickled) and rebuilt only if the config changes."""
        from grits_lab.config import config_fingerprint

        key = config_fingerprint(sim_config)
        if self._env is None or key != self._env_key:
            self.close_env()
            from grits_lab.sim.env import ScoopEnv

            self._env = ScoopEnv(sim_config)
            self._env_key = key
        return self._env

    def close_env(self) -> None:
        if self._env is not None:
            try:
                self._env.close()
            finally:
                self._env = None
                self._env_key = None

    def function(self, work: str) -> WorkFn:
        if work not in self._functions:
            self._functions[work] = import_work(work)
        return self._functions[work]

    def close(self) -> None:
        self.close_env()
        for value in self._cache.values():
            close = getattr(value, "close", None)
            if callable(close):
                close()
        self._cache.clear()


def execute_spec(spec: EpisodeSpec, context: WorkerContext) -> EpisodeResult:
    """Run one spec; an exception becomes a failed result (with its error) instead of ending the job."""
    start = time.perf_counter()
    try:
        payload = context.function(spec.work)(spec, context)
    except Exception as exc:  # the job goes on; the failure is recorded with its cause
        # A simulator that raised mid-episode may be in any state: rebuild it for the next spec.
        context.close_env()
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
