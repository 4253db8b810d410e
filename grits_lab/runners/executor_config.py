"""ExecutorConfig: the `executor:` section of a job config, and the one place an executor is chosen."""

from __future__ import annotations

import os
import socket
import time
from dataclasses import dataclass, field
from typing import Any, Literal

from grits_lab.config import require
from grits_lab.errors import GritsError
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


# How long a cluster address may refuse or ignore connections (a head still starting) before the
# job is refused; Ray itself retries for minutes.
CONNECT_TIMEOUT_S = 10.0


def cluster_address(config: ExecutorConfig) -> str | None:
    """The Ray cluster `config` runs on (its `address`, else RAY_ADDRESS), or None for a local Ray."""
    if config.backend != "ray":
        return None
    return config.address or os.environ.get("RAY_ADDRESS") or None


def check_reachable(address: str | None, timeout_s: float | None = None) -> None:
    """Refuse, in one line, a Ray cluster address where nothing answers; no Ray import, nothing started.

    Only a TCP connection to host:port is tried ("auto" and other forms without a port are left to
    Ray), retried until `timeout_s` (default CONNECT_TIMEOUT_S) so that a head still starting is met.
    """
    if not address:
        return
    target = address.split("://", 1)[-1].rstrip("/")
    host, sep, port_text = target.rpartition(":")
    if not sep or not port_text.isdigit() or not host:
        return
    host = host.strip("[]")
    deadline = time.monotonic() + (CONNECT_TIMEOUT_S if timeout_s is None else timeout_s)
    while True:
        try:
            with socket.create_connection((host, int(port_text)), timeout=min(5.0, max(0.5, deadline - time.monotonic()))):
                return
        except OSError as exc:
            if isinstance(exc, socket.gaierror) or time.monotonic() >= deadline:
                reason = exc.strerror or type(exc).__name__
                raise GritsError(f"cannot connect to the Ray cluster at {address}: nothing answers at "
                                 f"{host}:{port_text} ({reason}); is the head running (`ray start --head`)?") from None
        time.sleep(0.5)


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
