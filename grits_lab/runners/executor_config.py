"""ExecutorConfig: the `executor:` section of a job config, and the one place an executor is chosen."""

from __future__ import annotations

import contextlib
import os
import socket
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Iterator, Literal

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
    # Seconds a replacement for a lost worker may wait for a CPU (its node gone) before the pool
    # shrinks to the workers that remain.
    replace_timeout_s: float = 30.0

    def __post_init__(self) -> None:
        require(self.workers is None or self.workers >= 1, "executor.workers", self.workers, "at least 1 or null")
        require(self.num_cpus is None or self.num_cpus >= 1, "executor.num_cpus", self.num_cpus, "at least 1 or null")
        require(self.cpus_per_worker > 0, "executor.cpus_per_worker", self.cpus_per_worker, "positive")
        require(self.max_in_flight_per_worker >= 1, "executor.max_in_flight_per_worker", self.max_in_flight_per_worker, "at least 1")
        require(self.max_attempts >= 1, "executor.max_attempts", self.max_attempts, "at least 1")
        require(self.replace_timeout_s > 0, "executor.replace_timeout_s", self.replace_timeout_s, "positive")


# How long a cluster address may refuse or ignore connections (a head still starting) before the
# job is refused; Ray itself retries for minutes.
CONNECT_TIMEOUT_S = 10.0


def cluster_address(config: ExecutorConfig) -> str | None:
    """The Ray cluster `config` runs on (its `address`, else RAY_ADDRESS), or None for a local Ray."""
    if config.backend != "ray":
        return None
    return config.address or os.environ.get("RAY_ADDRESS") or None


def check_reachable(address: str | None, timeout_s: float | None = None) -> None:
    """Refuse, in one line, a Ray cluster address where nothing answers or that refuses this
    client's token; nothing is started on the cluster.

    A TCP connection to host:port is tried ("auto" and other forms without a port are left to
    Ray), retried until `timeout_s` (default CONNECT_TIMEOUT_S) so that a head still starting is
    met; then the head's GCS is asked once whether this client's token is accepted (not for a
    `ray://` client address, whose server checks it on connect).
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
                break
        except OSError as exc:
            if isinstance(exc, socket.gaierror) or time.monotonic() >= deadline:
                reason = exc.strerror or type(exc).__name__
                raise GritsError(f"cannot connect to the Ray cluster at {address}: nothing answers at "
                                 f"{host}:{port_text} ({reason}); is the head running (`ray start --head`)?") from None
        time.sleep(0.5)
    if "://" not in address:
        _check_token(address, f"{host}:{port_text}")


def _check_token(address: str, gcs_address: str) -> None:
    """Ask the GCS at `gcs_address` for nothing, with this client's token: a rejected token is a
    GritsError (token_refusal); anything else is left to `ray.init`, which reports it."""
    import threading

    if os.environ.get("RAY_AUTH_MODE", "").lower() == "token" and auth_token_source() is None:
        raise GritsError(token_refusal(address))  # Ray's client would abort the process over it
    try:
        from ray._raylet import GcsClient
        from ray.exceptions import AuthenticationError
    except ImportError:  # another Ray: the connection itself reports a refused token
        return
    outcome: list[BaseException | None] = []

    def ask() -> None:
        try:
            GcsClient(address=gcs_address).internal_kv_get(b"grits-lab-token-check", None, timeout=5)
            outcome.append(None)
        except BaseException as exc:  # noqa: BLE001 - only a refused token is reported here
            outcome.append(exc)

    with _stderr_silenced():  # the GCS client logs its refusal on fd 2: the user gets one line, below
        thread = threading.Thread(target=ask, daemon=True)
        thread.start()
        thread.join(15.0)
    if outcome and isinstance(outcome[0], AuthenticationError):
        raise GritsError(token_refusal(address))


def token_refusal(address: str) -> str:
    """The one line for a cluster that refused this client: no token sent, or a token that is not the cluster's."""
    source = auth_token_source()
    if os.environ.get("RAY_AUTH_MODE", "").lower() != "token":
        return (f"the Ray cluster at {address} requires token authentication and this client sent no token: set "
                "RAY_AUTH_MODE=token and make its token available (`ray get-auth-token` on the head; ~/.ray/auth_token or RAY_AUTH_TOKEN)")
    if source is None:
        where = os.environ.get("RAY_AUTH_TOKEN_PATH") or "~/.ray/auth_token"
        return (f"RAY_AUTH_MODE=token but no token to send to the Ray cluster at {address}: {where} does not exist and "
                "RAY_AUTH_TOKEN is not set; copy the output of `ray get-auth-token` on the head there")
    return (f"the Ray cluster at {address} rejected the token from {source}: it is not this cluster's token; "
            "copy the output of `ray get-auth-token` on the head there")


def auth_token_source() -> str | None:
    """Where Ray takes this client's token from (RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH, ~/.ray/auth_token), or None."""
    if os.environ.get("RAY_AUTH_TOKEN"):
        return "RAY_AUTH_TOKEN"
    path = os.environ.get("RAY_AUTH_TOKEN_PATH")
    if path:
        return path if os.path.isfile(path) else None
    default = os.path.expanduser("~/.ray/auth_token")
    return default if os.path.isfile(default) else None


@contextlib.contextmanager
def _stderr_silenced() -> Iterator[None]:
    """Point file descriptor 2 at /dev/null for the block (native libraries write there directly)."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


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
        replace_timeout_s=config.replace_timeout_s,
    )
