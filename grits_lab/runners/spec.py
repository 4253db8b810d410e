"""Episode specs and results: the picklable units of work that executors send to workers and stream back.

A spec carries *what* to run (`work`: a module-level function, pickled by reference) and everything needed to replay that episode alone (its seed, food, level, trajectory and
free-form parameters). Nothing in a spec holds a simulator, a client or a model: those live in the
worker and are built there, so a spec can cross process and machine boundaries.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np


WorkFn = Callable[["EpisodeSpec", Any], Any]


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode to run.

    episode_id: unique name of the episode within a job (also its file name in a dataset).
    work: a module-level function (importable in the worker, so it pickles by reference), called
        there as ``work(spec, context) -> payload`` with the worker's `WorkerContext`.
    seed: the episode's seed, derived from the job's root seed and the episode's identity.
    food, level: the food and quantity level, when the work is a scooping episode.
    trajectory: (T, 9) or (T, 7) commanded spoon poses, when the work replays one.
    params: anything else the work function needs (plain, picklable values).
    """

    episode_id: str
    work: WorkFn
    seed: int
    food: str | None = None
    level: str | None = None
    trajectory: np.ndarray | None = None
    params: dict[str, Any] = field(default_factory=dict)

    def replace(self, **changes: Any) -> "EpisodeSpec":
        return dataclasses.replace(self, **changes)


@dataclass
class EpisodeResult:
    """What came back for one spec.

    ok is False when the work function raised (error holds ``"Type: message"``, traceback the
    formatted stack) or when its worker died more often than the executor retries. payload is the
    work function's return value (None on failure). attempts counts runs of this spec, > 1 after a
    worker was lost. worker names the process that produced the result (host:pid).
    """

    episode_id: str
    ok: bool
    payload: Any = None
    error: str = ""
    traceback: str = ""
    wall_time_s: float = 0.0
    attempts: int = 1
    worker: str = ""
    spec: EpisodeSpec | None = None
