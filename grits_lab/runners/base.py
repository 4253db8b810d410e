"""The executor interface shared by the serial and the Ray executors: submit specs, poll results.

Two levels: `map_unordered(specs)` streams results for a known list (or a lazy iterator, pulled
only when a worker is free, so memory stays bounded), and `submit` / `capacity` / `poll` for jobs
that decide what to run next from the results so far (the balanced spillage dataset).
"""

from __future__ import annotations

import abc
from typing import Iterable, Iterator

from grits_lab.runners.spec import EpisodeResult, EpisodeSpec


class Executor(abc.ABC):
    """Runs episode specs on workers; results come back in completion order."""

    num_workers: int = 1

    @abc.abstractmethod
    def submit(self, spec: EpisodeSpec) -> None:
        """Queue one spec; it starts as soon as a worker slot is free."""

    @abc.abstractmethod
    def capacity(self) -> int:
        """How many more specs can be submitted before the queue holds work no worker can start."""

    @abc.abstractmethod
    def pending(self) -> int:
        """Specs submitted whose result has not been returned by `poll` yet."""

    @abc.abstractmethod
    def poll(self, timeout: float | None = None) -> list[EpisodeResult]:
        """Results finished since the last call; waits up to `timeout` s (None: until one is ready)."""

    def close(self) -> None:
        """Release the workers."""

    def map_unordered(self, specs: Iterable[EpisodeSpec]) -> Iterator[EpisodeResult]:
        """Stream a result for every spec, keeping at most `capacity` specs in flight."""
        source = iter(specs)
        exhausted = False
        while True:
            while not exhausted and self.capacity() > 0:
                spec = next(source, None)
                if spec is None:
                    exhausted = True
                    break
                self.submit(spec)
            if exhausted and self.pending() == 0:
                return
            yield from self.poll()

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
