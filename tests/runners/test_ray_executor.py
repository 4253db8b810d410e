"""Ray executor: same records as serial, killed workers replaced, failures recorded (one Ray per module)."""

import os
import signal
import threading
import time

import pytest

ray = pytest.importorskip("ray")

from grits_lab.runners import EpisodeSpec, SerialExecutor, probe_episode  # noqa: E402
from grits_lab.runners.ray_executor import RayExecutor  # noqa: E402

pytestmark = pytest.mark.ray


@pytest.fixture(scope="module", autouse=True)
def ray_session():
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    yield
    ray.shutdown()


def _specs(n, **params):
    return [EpisodeSpec(episode_id=f"ep{i:03d}", work=probe_episode, seed=7 + i, params=dict(params)) for i in range(n)]


def _records(results):
    return {r.episode_id: (r.ok, r.payload, r.error) for r in results}


def test_ray_and_serial_give_identical_records():
    specs = _specs(8)
    specs[3] = specs[3].replace(params={"fail": True})
    with SerialExecutor() as ex:
        serial = _records(ex.map_unordered(specs))
    with RayExecutor(workers=2) as ex:
        assert ex.num_workers == 2
        parallel = _records(ex.map_unordered(specs))
    assert parallel == serial
    assert not parallel["ep003"][0] and "asked to fail" in parallel["ep003"][2]


def test_more_workers_than_cpus_is_clamped_not_deadlocked():
    with RayExecutor(workers=5) as ex:
        assert ex.num_workers == 2
        results = list(ex.map_unordered(_specs(4)))
    assert len(results) == 4 and all(r.ok for r in results)


def test_killed_worker_is_replaced_and_its_episode_rerun():
    specs = _specs(6, sleep_s=0.6)
    with SerialExecutor() as ex:
        expected = _records(ex.map_unordered(_specs(6)))
    with RayExecutor(workers=2) as ex:
        victim = ex.worker_pids()[0]
        killer = threading.Timer(0.3, os.kill, args=(victim, signal.SIGKILL))
        killer.start()
        results = list(ex.map_unordered(specs))
        killer.join()
        pids_after = ex.worker_pids()
    assert victim not in pids_after
    assert _records(results) == expected
    assert max(r.attempts for r in results) == 2
    assert all(r.ok for r in results)


def test_poll_interface_bounds_in_flight():
    with RayExecutor(workers=2, max_in_flight_per_worker=1) as ex:
        for spec in _specs(2):
            ex.submit(spec)
        assert ex.capacity() == 0
        seen = []
        while ex.pending():
            seen += ex.poll(timeout=30)
    assert sorted(r.episode_id for r in seen) == ["ep000", "ep001"]
