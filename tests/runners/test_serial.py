"""Serial executor and work resolution: no Ray needed."""

import pytest

from grits_lab.errors import InputError
from grits_lab.runners import EpisodeSpec, ExecutorConfig, SerialExecutor, register_work
from grits_lab.runners.work import resolve_work_path
from grits_lab.errors import ConfigError
from grits_lab.config import config_from_dict


def _specs(n, **params):
    return [EpisodeSpec(episode_id=f"ep{i:03d}", work="probe", seed=100 + i, params=params) for i in range(n)]


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


def test_work_by_path_and_registered_kind():
    register_work("probe_alias", "grits_lab.runners.work:probe_episode")
    spec = EpisodeSpec("a", work="probe_alias", seed=1)
    spec_path = EpisodeSpec("a", work="grits_lab.runners.work:probe_episode", seed=1)
    with SerialExecutor() as ex:
        (r1,) = list(ex.map_unordered([spec]))
        (r2,) = list(ex.map_unordered([spec_path]))
    assert r1.payload == r2.payload


def test_unknown_work_is_a_clear_error():
    with pytest.raises(InputError, match="unknown work kind 'nope'"):
        resolve_work_path("nope")
    with SerialExecutor() as ex:
        (r,) = list(ex.map_unordered([EpisodeSpec("a", work="no_such_module_x:fn", seed=1)]))
    assert not r.ok and "cannot import work module" in r.error


def test_executor_config_rejects_bad_values():
    with pytest.raises(ConfigError, match="executor.workers"):
        ExecutorConfig(workers=0)
    with pytest.raises(ConfigError, match="unknown key `wokers`"):
        config_from_dict(ExecutorConfig, {"wokers": 2})
