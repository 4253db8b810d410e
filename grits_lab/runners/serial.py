"""The in-process executor: same interface as the Ray executor, for tests, debugging and 1-core runs."""

from __future__ import annotations

import collections

from grits_lab.runners.base import Executor
from grits_lab.runners.spec import EpisodeResult, EpisodeSpec
from grits_lab.runners.work import WorkerContext, execute_spec


class SerialExecutor(Executor):
    """Runs each spec in the calling process, one at a time, with one persistent WorkerContext."""

    num_workers = 1

    def __init__(self) -> None:
        self._queue: collections.deque[EpisodeSpec] = collections.deque()
        self._context = WorkerContext(0)

    def submit(self, spec: EpisodeSpec) -> None:
        self._queue.append(spec)

    def capacity(self) -> int:
        return 1 - len(self._queue)

    def pending(self) -> int:
        return len(self._queue)

    def poll(self, timeout: float | None = None) -> list[EpisodeResult]:
        if not self._queue:
            return []
        return [execute_spec(self._queue.popleft(), self._context)]

    def close(self) -> None:
        self._context.close()
