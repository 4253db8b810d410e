"""The Ray executor's bookkeeping when a node with several workers is lost, driven through `poll` with
Ray's calls replaced by a script (no Ray started): the workers are given up a moment apart, in
different polls, and reported in one line."""

from __future__ import annotations

import itertools
import logging

import pytest

pytest.importorskip("ray")

from ray.exceptions import RayActorError  # noqa: E402

from grits_lab.errors import GritsError  # noqa: E402
from grits_lab.runners import ray_executor  # noqa: E402
from grits_lab.runners.ray_executor import RayExecutor, _Slot  # noqa: E402
from grits_lab.runners.spec import EpisodeResult, EpisodeSpec  # noqa: E402

_refs = itertools.count()


class _Method:
    def __init__(self, name: str):
        self.name = name

    def remote(self, *args):
        return (self.name, next(_refs))


class _Actor:
    def __init__(self, *args):
        self.pid, self.run = _Method("pid"), _Method("run")


class _ActorClass:
    def options(self, **kwargs):
        return self

    def remote(self, index):
        return _Actor()


class _Cluster:
    """What the executor asks Ray: a clock, the cluster's CPUs, which refs are ready and what they hold."""

    def __init__(self, monkeypatch, cpus: float):
        self.now, self.cpus, self.ready, self.lost = 1000.0, cpus, [], set()
        for name, fn in {"wait": self.wait, "get": self.get, "kill": lambda *a, **k: None,
                         "cluster_resources": lambda: {"CPU": self.cpus}}.items():
            monkeypatch.setattr(ray_executor.ray, name, fn)
        monkeypatch.setattr(ray_executor, "time", self)

    def monotonic(self) -> float:
        return self.now

    def wait(self, refs, num_returns, timeout):
        ready = [r for r in refs if r in self.ready][:num_returns]
        return ready, [r for r in refs if r not in ready]

    def get(self, ref, timeout=None):
        self.ready.remove(ref)
        if ref in self.lost:
            raise RayActorError()
        return EpisodeResult(episode_id="x", ok=True)


def _executor(workers: int, replace_timeout_s: float = 5.0) -> RayExecutor:
    ex = RayExecutor.__new__(RayExecutor)  # the pool as __init__ leaves it, without starting Ray
    ex._owns_ray, ex.num_workers, ex.cpus_per_worker = False, workers, 1.0
    ex.max_in_flight_per_worker, ex.max_attempts, ex.replace_timeout_s = 1, 3, replace_timeout_s
    ex._actor_cls = _ActorClass()
    ex._slots = [_Slot(actor=_Actor(), generation=0) for _ in range(workers)]
    ex._queue, ex._in_flight, ex._ready_results, ex._lost_reasons = ray_executor.collections.deque(), {}, [], []
    return ex


def _spec(i: int) -> EpisodeSpec:
    return EpisodeSpec(episode_id=f"ep{i}", work=None, seed=i)


def _lost_lines(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if "not replaced" in r.getMessage()]


def _lose_two_workers(cluster: _Cluster, ex: RayExecutor) -> None:
    """Workers 1 and 2 (one node) die; their episodes come back as lost 0.3 s apart, each in its own poll."""
    refs = {ex._in_flight[r][0]: r for r in ex._in_flight}
    for index, dt in ((1, 0.0), (2, 0.3)):
        cluster.now += dt
        cluster.lost.add(refs[index])
        cluster.ready.append(refs[index])
        assert ex.poll(timeout=0) == []


def test_the_workers_of_a_lost_node_given_up_in_different_polls_are_reported_in_one_line(monkeypatch, caplog):
    cluster = _Cluster(monkeypatch, cpus=3)  # the cluster does not show the lost node's CPUs yet
    ex = _executor(3)
    for i in range(3):
        ex.submit(_spec(i))
    with caplog.at_level(logging.WARNING, logger=ray_executor.__name__):
        _lose_two_workers(cluster, ex)
        assert sum(s.ready_ref is not None for s in ex._slots) == 2  # two replacements awaited, never placed
        cluster.now += 4.8  # 5 s after the first replacement started: given up; the second's 0.3 s later
        ex.poll(timeout=0)
        assert ex.num_workers == 2
        cluster.now += 0.3
        ex.poll(timeout=0)
        assert ex.num_workers == 1
        ex.close()
    assert _lost_lines(caplog) == ["2 Ray workers were lost and not replaced (no CPU took a replacement within 5 s): continuing with 1 worker"]


def test_one_worker_lost_is_one_line_in_the_singular_and_a_job_ending_first_still_says_it(monkeypatch, caplog):
    cluster = _Cluster(monkeypatch, cpus=3)
    ex = _executor(3)
    for i in range(3):
        ex.submit(_spec(i))
    with caplog.at_level(logging.WARNING, logger=ray_executor.__name__):
        _lose_two_workers(cluster, ex)
        cluster.now += 4.8
        ex.poll(timeout=0)  # one given up; the other replacement is still awaited when the job ends
        ex.close()
    assert _lost_lines(caplog) == ["a Ray worker was lost and not replaced (no CPU took a replacement within 5 s): continuing with 2 workers"]


def test_every_worker_lost_is_one_error(monkeypatch):
    cluster = _Cluster(monkeypatch, cpus=2)
    ex = _executor(2)
    for i in range(2):
        ex.submit(_spec(i))
    for ref in list(ex._in_flight):
        cluster.lost.add(ref)
        cluster.ready.append(ref)
    ex.poll(timeout=0)
    cluster.now += 5.0
    with pytest.raises(GritsError, match=r"^every Ray worker was lost \(no CPU took a replacement within 5 s\); rerun"):
        ex.poll(timeout=0)
