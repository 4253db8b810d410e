"""ExecutorConfig: the `executor:` section of a job config, and the one place an executor is chosen."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from grits_lab.config import require
from grits_lab.runners.base import Executor


@dataclass
class ExecutorConfig:
    # "ray" (default) runs on a local Ray sized to the machine, or on a cluster; "serial" runs
    # everything in this process (debugging, profiling, 1-core machines).
    backend: Literal["ray", "serial"] = "ray"
    # Number of worker actors; null = as many as the cluster's CPUs fit.
    workers: int | None = None
    # Existing cluster to run on ("auto", "ray://head:10001", "head:6379"); null = RAY_ADDRESS
    # if set, else a local Ray started for this job.
    address: str | None = None
    # CPUs a local Ray may use; null = all cores of this machine.
    num_cpus: int | None = None
    cpus_per_worker: float = 1.0
    max_in_flight_per_worker: int = 1
    # Runs of an episode before a repeatedly dying worker marks it failed.
    max_attempts: int = 3
    # Ray runtime_env for clusters whose nodes lack grits_lab, e.g. {working_dir: "."}.
    runtime_env: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        require(self.workers is None or self.workers >= 1, "executor.workers", self.workers, "at least 1 or null")
        require(self.num_cpus is None or self.num_cpus >= 1, "executor.num_cpus", self.num_cpus, "at least 1 or null")
        require(self.cpus_per_worker > 0, "executor.cpus_per_worker", self.cpus_per_worker, "positive")
        require(self.max_in_flight_per_worker >= 1, "executor.max_in_flight_per_worker", self.max_in_flight_per_worker, "at least 1")
        require(self.max_attempts >= 1, "executor.max_attempts", self.max_attempts, "at least 1")


def make_executor(config: ExecutorConfig) -> Executor:
    """The executor `config` describes (imports Ray only for the Ray backend)."""
    if config.backend == "serial":
        from grits_lab.runners.serial import SerialExecutor

        return SerialExecutor()
    from grits_lab.runners.ray_executor import RayExecutor

    return RayExecutor(
        workers=config.workers,
        address=config.address,
        num_cpus=config.num_cpus,
        cpus_per_worker=config.cpus_per_worker,
        max_in_flight_per_worker=config.max_in_flight_per_worker,
        max_attempts=config.max_attempts,
        runtime_env=config.runtime_env or None,
    )
