"""Serial executor and the worker context: no Ray needed."""

import pytest

from grits_lab.runners import EpisodeSpec, ExecutorConfig, SerialExecutor, WorkerContext, execute_spec, probe_episode
from grits_lab.errors import ConfigError
from grits_lab.config import config_from_dict


def _specs(n, **params):
    return [EpisodeSpec(episode_id=f"ep{i:03d}", work=probe_episode, seed=100 + i, params=params) for i in range(n)]


def test_serial_runs_every_spec_and_same_seed_same_payload():
    with SerialExecutor() as ex:
        first = {r.episode_id: r.payload for r in ex.map_unordered(_specs(5))}
    with SerialExecutor() as ex:
        second = {r.episode_id: r.payload for r in ex.map_unordered(_specs(5))}
    assert sorted(first) == [f"ep{i:03d}" for i in range(5)]
    assert first == second
    assert first["ep000"]["value"] != first["ep001"]["value"]


def test_failing_episode_is_recorded_and_job_goes_on():
    specs = _specs(3)
    specs[1] = specs[1].replace(params={"fail": True})
    with SerialExecutor() as ex:
        results = {r.episode_id: r for r in ex.map_unordered(specs)}
    assert results["ep000"].ok and results["ep002"].ok
    assert not results["ep001"].ok
    assert results["ep001"].error.startswith("ValueError: probe episode ep001 asked to fail")
    assert "Traceback" in results["ep001"].traceback


class _Resource:
    built = 0

    def __init__(self, key):
        self.key = key
        self.closed = False
        _Resource.built += 1

    def close(self):
        self.closed = True


def _use_resource(spec, context):
    resource = context.reusable(spec.params["key"], lambda: _Resource(spec.params["key"]))
    if spec.params.get("fail"):
        raise RuntimeError("the simulator broke")
    return id(resource)


def test_reusable_resource_is_kept_per_key_and_discarded_after_a_failure():
    context = WorkerContext(0)
    _Resource.built = 0
    run = lambda key, **extra: execute_spec(EpisodeSpec("a", work=_use_resource, seed=1, params={"key": key, **extra}), context)
    first, again = run("sim-a"), run("sim-a")
    assert first.ok and first.payload == again.payload and _Resource.built == 1
    kept = context.reusable("sim-a", lambda: None)
    assert run("sim-b").ok and _Resource.built == 2 and kept.closed  # a new key closes the old one
    failed = run("sim-b", fail=True)
    assert not failed.ok and "RuntimeError: the simulator broke" in failed.error
    assert run("sim-b").ok and _Resource.built == 3  # rebuilt after the failure
    context.close()


def test_a_failed_result_keeps_the_spec_and_its_work_function():
    with SerialExecutor() as ex:
        (r,) = list(ex.map_unordered([EpisodeSpec("a", work=probe_episode, seed=1, params={"fail": True})]))
    assert not r.ok and r.spec.work is probe_episode


def test_executor_config_rejects_bad_values():
    with pytest.raises(ConfigError, match="executor.workers"):
        ExecutorConfig(workers=0)
    with pytest.raises(ConfigError, match="unknown key `wokers`"):
        config_from_dict(ExecutorConfig, {"wokers": 2})
