"""The Ray executor: a pool of actors, each holding one simulator, fed specs with a bounded number in flight.

Sizing. Each actor reserves `cpus_per_worker` CPUs (default 1) for its whole life, and the
executor starts no more actors than the cluster's CPUs can hold, so every actor is scheduled and
no work is left waiting for a CPU an actor will never release (on a 2-core machine two 1-CPU
actors take both CPUs: that is safe here because all work runs *in* the actors; the executor never
submits plain Ray tasks). Episodes are pure CPU, one thread each, so one actor per core is the
right size; the driver only waits and writes files.

Faults. A spec whose actor dies (kill -9, node lost, out of memory) is re-run from its seed on a
live actor, up to `max_attempts` runs, and a replacement actor is started; work goes only to
actors that have answered. A replacement that the cluster cannot place (its node is gone and no
CPU is left for it) is given up after `replace_timeout_s`, or at once when the cluster's CPUs
already show it, and the pool shrinks to the actors that remain. One line says so once no other
replacement is still awaited, so that the workers of one lost node, whose replacements are given up
a moment apart, are reported together ("2 Ray workers were lost and not replaced (...): continuing
with 1 worker"). A spec
whose work function raises comes back as a failed result with its error (the worker catches it),
and the job goes on.

Where Ray runs: an explicit `address`, else the RAY_ADDRESS environment variable, else a local
Ray started here and sized to the machine. If Ray is already initialized in this process (tests,
notebooks) it is used as is and left running on close.
"""

from __future__ import annotations

import collections
import logging
import math
import os
import time
from dataclasses import dataclass
from typing import Any

import ray
from ray.exceptions import GetTimeoutError, RayActorError, RayError

from grits_lab.errors import GritsError
from grits_lab.runners.base import Executor
from grits_lab.runners.local_ray import make_token_private
from grits_lab.runners.spec import EpisodeResult, EpisodeSpec
from grits_lab.runners.work import WorkerContext, execute_spec

log = logging.getLogger(__name__)

try:  # newer Ray raises this while an actor is restarting or unreachable
    from ray.exceptions import ActorUnavailableError
except ImportError:  # pragma: no cover - older Ray
    ActorUnavailableError = RayActorError

_LOST_WORKER = (RayActorError, ActorUnavailableError)


def _connect(address: str, kwargs: dict[str, Any]) -> None:
    """ray.init on an existing cluster, with one clear line when that fails."""
    from grits_lab.runners.executor_config import check_reachable, token_refusal

    check_reachable(address)  # Ray retries an unreachable address for minutes
    try:
        ray.init(address=address, **kwargs)
    except Exception as exc:  # Ray raises ConnectionError, RuntimeError or its own types here
        text = f"{type(exc).__name__}: {exc}"
        chain, cause = [], exc
        while cause is not None and len(chain) < 10:
            chain.append(f"{type(cause).__name__}: {cause}".lower())
            cause = cause.__cause__ or cause.__context__
        if any("authentication" in c or "auth token" in c for c in chain):
            raise GritsError(token_refusal(address)) from None
        raise GritsError(f"cannot connect to the Ray cluster at {address}: {text.splitlines()[0]}") from None


class _EpisodeWorker:
    """Actor body: one WorkerContext (so one simulator) per actor process."""

    def __init__(self, worker_index: int):
        self._context = WorkerContext(worker_index)

    def pid(self) -> int:
        return os.getpid()

    def peak_rss_mb(self) -> float:
        """Peak resident memory of this worker process so far (Linux reports kB)."""
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    def run(self, spec: EpisodeSpec) -> EpisodeResult:
        result = execute_spec(spec, self._context)
        result.spec = None  # the driver still has it; do not ship trajectories back
        return result


@dataclass
class _Slot:
    actor: Any
    generation: int
    in_flight: int = 0
    ready_ref: Any = None  # a replacement's first answer, awaited; None: the actor has answered
    started: float = 0.0  # when a replacement was started (time.monotonic)


class RayExecutor(Executor):
    """Actors each holding one simulator; results streamed with `ray.wait`.

    workers: number of actors (None: as many as the cluster's CPUs allow).
    address: Ray cluster address ("auto", "ray://host:10001", "host:6379"); None uses RAY_ADDRESS
        or starts a local Ray with `num_cpus` CPUs (None: this machine's core count).
    cpus_per_worker: CPUs each actor reserves.
    max_in_flight_per_worker: specs queued on each actor at once; 1 keeps a killed worker from
        taking queued specs down with it, 2 hides the driver's round trip for very short episodes.
    max_attempts: runs of a spec before a lost worker marks it failed.
    runtime_env: passed to ray.init when connecting (e.g. {"working_dir": "."} for a cluster whose
        nodes do not have grits_lab installed).
    replace_timeout_s: how long a replacement for a lost actor may wait for a CPU before the pool
        shrinks instead.
    """

    def __init__(
        self,
        workers: int | None = None,
        address: str | None = None,
        num_cpus: int | None = None,
        cpus_per_worker: float = 1.0,
        max_in_flight_per_worker: int = 1,
        max_attempts: int = 3,
        runtime_env: dict[str, Any] | None = None,
        startup_timeout_s: float = 120.0,
        replace_timeout_s: float = 30.0,
    ):
        self._owns_ray = False
        if not ray.is_initialized():
            address = address or os.environ.get("RAY_ADDRESS") or None
            kwargs: dict[str, Any] = {"include_dashboard": False, "logging_level": logging.WARNING}
            if runtime_env:
                kwargs["runtime_env"] = runtime_env
            if address:
                _connect(address, kwargs)
            else:
                # "local": always a fresh Ray of our own, even if a stale address file of an
                # earlier `ray start` is left in the temp dir.
                ray.init(address="local", num_cpus=num_cpus or os.cpu_count() or 1, **kwargs)
                make_token_private()  # what listens where, and why: grits_lab/runners/local_ray.py
            self._owns_ray = True
        cluster_cpus = float(ray.cluster_resources().get("CPU", 0.0))
        fit = int(math.floor(cluster_cpus / cpus_per_worker + 1e-9))
        if fit < 1:
            raise GritsError(
                f"the Ray cluster has {cluster_cpus:g} CPUs, fewer than cpus_per_worker={cpus_per_worker:g}"
            )
        if workers is not None and workers > fit:
            # More actors than CPUs would leave some unscheduled forever: wait on them = deadlock.
            log.warning("asked for %d workers but the cluster fits %d (%g CPUs); using %d", workers, fit, cluster_cpus, fit)
        self.num_workers = min(workers or fit, fit)
        self.cpus_per_worker = cpus_per_worker
        self.max_in_flight_per_worker = max(1, int(max_in_flight_per_worker))
        self.max_attempts = max(1, int(max_attempts))
        self.replace_timeout_s = float(replace_timeout_s)
        self._actor_cls = ray.remote(_EpisodeWorker)
        self._slots: list[_Slot | None] = [self._start_actor(i, 0) for i in range(self.num_workers)]
        self._queue: collections.deque[tuple[EpisodeSpec, int]] = collections.deque()
        self._in_flight: dict[Any, tuple[int, int, EpisodeSpec, int]] = {}
        self._ready_results: list[EpisodeResult] = []
        self._lost_reasons: list[str] = []  # one per worker dropped and not yet reported (_report_lost)
        try:
            ray.get([s.actor.pid.remote() for s in self._live()], timeout=startup_timeout_s)
        except GetTimeoutError:
            self.close()
            raise GritsError(
                f"{self.num_workers} Ray workers could not start within {startup_timeout_s:g} s "
                f"(cluster CPUs: {cluster_cpus:g}, cpus_per_worker: {cpus_per_worker:g})"
            ) from None

    def _start_actor(self, index: int, generation: int) -> _Slot:
        actor = self._actor_cls.options(num_cpus=self.cpus_per_worker, max_restarts=0).remote(index)
        return _Slot(actor=actor, generation=generation)

    def _live(self) -> list[_Slot]:
        """Actors that have answered (work goes only to them)."""
        return [s for s in self._slots if s is not None and s.ready_ref is None]

    def worker_pids(self) -> list[int]:
        """Process ids of the current actors (for monitoring, and for fault-injection tests)."""
        return ray.get([s.actor.pid.remote() for s in self._live()])

    def worker_peak_rss_mb(self) -> list[float]:
        """Peak resident memory of each current actor (MB)."""
        return ray.get([s.actor.peak_rss_mb.remote() for s in self._live()])

    def submit(self, spec: EpisodeSpec) -> None:
        self._queue.append((spec, 1))
        self._dispatch()

    def capacity(self) -> int:
        total = self.num_workers * self.max_in_flight_per_worker
        return total - len(self._in_flight) - len(self._queue)

    def pending(self) -> int:
        return len(self._in_flight) + len(self._queue) + len(self._ready_results)

    def _dispatch(self) -> None:
        for index, slot in enumerate(self._slots):
            if slot is None or slot.ready_ref is not None:
                continue
            while self._queue and slot.in_flight < self.max_in_flight_per_worker:
                spec, attempt = self._queue.popleft()
                ref = slot.actor.run.remote(spec)
                slot.in_flight += 1
                self._in_flight[ref] = (index, slot.generation, spec, attempt)

    def poll(self, timeout: float | None = None) -> list[EpisodeResult]:
        results, self._ready_results = self._ready_results, []
        if results or not (self._in_flight or self._queue):
            return results
        waiting = {s.ready_ref: i for i, s in enumerate(self._slots) if s is not None and s.ready_ref is not None}
        refs = list(self._in_flight) + list(waiting)
        if not refs:
            return results
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=0)
        if not ready:
            ready, _ = ray.wait(refs, num_returns=1, timeout=self._wait_bound(timeout))
        for ref in ready:
            if ref in waiting:
                self._replacement_answered(waiting[ref], ref)
                continue
            index, generation, spec, attempt = self._in_flight.pop(ref)
            slot = self._slots[index]
            if slot is not None and slot.generation == generation:
                slot.in_flight -= 1
            try:
                result: EpisodeResult = ray.get(ref)
            except _LOST_WORKER as exc:
                self._replace_actor(index, generation)
                if attempt < self.max_attempts:
                    log.warning("worker lost while running %s (attempt %d); re-running it from its seed", spec.episode_id, attempt)
                    self._queue.appendleft((spec, attempt + 1))
                    continue
                result = EpisodeResult(
                    episode_id=spec.episode_id,
                    ok=False,
                    error=f"WorkerLost: worker died on each of {attempt} attempts: {type(exc).__name__}",
                    attempts=attempt,
                )
            except RayError as exc:  # e.g. a result that cannot be fetched: record it, go on
                result = EpisodeResult(episode_id=spec.episode_id, ok=False, error=f"{type(exc).__name__}: {exc}", attempts=attempt)
            result.spec = spec
            result.attempts = attempt
            results.append(result)
        self._give_up_unplaced_replacements()
        self._report_lost()
        self._dispatch()
        return results

    def _wait_bound(self, timeout: float | None) -> float | None:
        """`timeout`, shortened to the moment the oldest awaited replacement is given up."""
        deadlines = [s.started + self.replace_timeout_s - time.monotonic() for s in self._slots if s is not None and s.ready_ref is not None]
        if not deadlines:
            return timeout
        bound = max(0.0, min(deadlines)) + 0.01
        return bound if timeout is None else min(timeout, bound)

    def _replace_actor(self, index: int, generation: int) -> None:
        slot = self._slots[index]
        if slot is None or slot.generation != generation:
            return  # already replaced (or given up) when another of its specs came back
        try:
            ray.kill(slot.actor, no_restart=True)
        except Exception:  # already gone
            pass
        others = sum(1 for s in self._slots if s is not None) - 1
        fit = int(math.floor(float(ray.cluster_resources().get("CPU", 0.0)) / self.cpus_per_worker + 1e-9))
        if others >= fit and others > 0:  # the cluster already shows fewer CPUs: no room for a replacement
            cpus = fit * self.cpus_per_worker
            self._shrink(index, f"the cluster has {cpus:g} CPU{'' if cpus == 1 else 's'} left")
            return
        replacement = self._start_actor(index, generation + 1)
        replacement.ready_ref = replacement.actor.pid.remote()
        replacement.started = time.monotonic()
        self._slots[index] = replacement

    def _replacement_answered(self, index: int, ref: Any) -> None:
        slot = self._slots[index]
        try:
            ray.get(ref)
        except RayError:  # lost before it ever ran (its node went away too)
            self._shrink(index, "a replacement was lost before it started")
            return
        slot.ready_ref = None

    def _give_up_unplaced_replacements(self) -> None:
        now = time.monotonic()
        late = [i for i, s in enumerate(self._slots) if s is not None and s.ready_ref is not None and now - s.started >= self.replace_timeout_s]
        if late:
            self._shrink(late, f"no CPU took a replacement within {self.replace_timeout_s:g} s")

    def _shrink(self, indices: list[int] | int, reason: str) -> None:
        """Drop these slots for good; the specs queued go to the actors that remain, and `_report_lost`
        says so in one line."""
        indices = [indices] if isinstance(indices, int) else indices
        for index in indices:
            slot = self._slots[index]
            if slot is not None:
                try:
                    ray.kill(slot.actor, no_restart=True)
                except Exception:
                    pass
            self._slots[index] = None
        self.num_workers = sum(1 for s in self._slots if s is not None)
        self._lost_reasons += [reason] * len(indices)
        if self.num_workers == 0:
            reasons = "; ".join(dict.fromkeys(self._lost_reasons))
            self._lost_reasons = []
            raise GritsError(f"every Ray worker was lost ({reasons}); rerun the job to resume it when the cluster has CPUs again")

    def _report_lost(self, *, now: bool = False) -> None:
        """One line for the workers dropped since the last one, once no replacement is still awaited
        (or `now`): the workers of a lost node are given up a moment apart, in different polls."""
        if not self._lost_reasons:
            return
        if not now and any(s is not None and s.ready_ref is not None for s in self._slots):
            return
        n, reasons = len(self._lost_reasons), "; ".join(dict.fromkeys(self._lost_reasons))
        self._lost_reasons = []
        lost = f"{n} Ray workers were" if n > 1 else "a Ray worker was"
        left = f"{self.num_workers} worker{'' if self.num_workers == 1 else 's'}"
        log.warning("%s lost and not replaced (%s): continuing with %s", lost, reasons, left)

    def close(self) -> None:
        if getattr(self, "_lost_reasons", None):
            self._report_lost(now=True)
        for slot in getattr(self, "_slots", []):
            if slot is None:
                continue
            try:
                ray.kill(slot.actor, no_restart=True)
            except Exception:
                pass
        self._slots = []
        self._in_flight = {}
        if self._owns_ray and ray.is_initialized():
            ray.shutdown()
            self._owns_ray = False
