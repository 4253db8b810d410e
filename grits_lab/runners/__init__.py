"""Parallel episode engine: executors (serial, Ray) that run picklable episode specs on workers.

The only package in grits_lab that imports Ray, and only when a Ray executor is made, so that
importing this package (and the CLI's --help) stays fast.
"""

from __future__ import annotations

from grits_lab.runners.base import Executor
from grits_lab.runners.executor_config import ExecutorConfig, make_executor
from grits_lab.runners.serial import SerialExecutor
from grits_lab.runners.spec import EpisodeResult, EpisodeSpec
from grits_lab.runners.work import WorkerContext, execute_spec, probe_episode

__all__ = [
    "EpisodeResult",
    "EpisodeSpec",
    "Executor",
    "ExecutorConfig",
    "SerialExecutor",
    "WorkerContext",
    "execute_spec",
    "make_executor",
    "probe_episode",
]
