"""Real simulated episodes on Ray workers give exactly the serial executor's records (one Ray per module)."""

import json
from pathlib import Path

import numpy as np
import pytest

ray = pytest.importorskip("ray")

from grits_lab.config import config_from_dict  # noqa: E402
from grits_lab.data.format import list_episode_files, read_episode  # noqa: E402
from grits_lab.collection.jobs import base_trajectory, run_collection  # noqa: E402
from grits_lab.collection.spillage_trials import SpillageConfig, make_trial_spec, source_bowl_region  # noqa: E402
from grits_lab.runners import SerialExecutor  # noqa: E402
from grits_lab.runners.ray_executor import RayExecutor  # noqa: E402

pytestmark = pytest.mark.ray

CAMERAS = [
    {"name": "front", "eye": [1.05, -0.15, 0.55], "target": [0.5, -0.1, 0.03], "width": 96, "height": 72},
    {"name": "side", "eye": [0.5, -0.75, 0.5], "target": [0.5, -0.05, 0.03], "width": 96, "height": 72},
]


@pytest.fixture(scope="module", autouse=True)
def ray_session():
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    yield
    ray.shutdown()


def test_serial_and_ray_give_identical_simulated_records():
    config = config_from_dict(SpillageConfig, {
        "kind": "spillage", "episodes": 4, "shapes": ["sphere", "cube"], "particles": {"fill_height": [0.005, 0.008]},
        "cloud": {"n_points": 128, "cad_surface_samples": 1000}, "sim": {"cameras": CAMERAS}, "exit": {"kind": "exit"},
    })
    base = base_trajectory(config)[:30]
    bowl = source_bowl_region(config)
    specs = [make_trial_spec(config, base, bowl, shape, k) for shape in ("sphere", "cube") for k in range(2)]
    with SerialExecutor() as ex:
        serial = {r.episode_id: r for r in ex.map_unordered(specs)}
    with RayExecutor(workers=2) as ex:
        parallel = {r.episode_id: r for r in ex.map_unordered(specs)}
    assert sorted(serial) == sorted(parallel) and len(serial) == 4
    for eid, r in serial.items():
        assert r.ok and parallel[eid].ok, (r.error, parallel[eid].error)
        assert parallel[eid].payload["meta"] == r.payload["meta"]
        for key, value in r.payload["arrays"].items():
            np.testing.assert_array_equal(parallel[eid].payload["arrays"][key], value, err_msg=f"{eid}:{key}")
    assert len({r.worker for r in parallel.values()}) == 2


def test_a_worker_killed_during_collect_loses_and_duplicates_nothing(tmp_path, kill_a_worker_mid_episode):
    data = {
        "kind": "spillage", "episodes": 4, "spill_fraction": 0.0, "shapes": ["sphere", "cube"], "particles": {"fill_height": [0.005, 0.005]},
        "cloud": {"n_points": 64, "cad_surface_samples": 500}, "sim": {"cameras": CAMERAS}, "exit": {"kind": "exit", "enabled": False},
        "raw_cloud": False,
    }
    serial = config_from_dict(SpillageConfig, {**data, "output_dir": str(tmp_path / "serial"), "executor": {"backend": "serial"}})
    ray_cfg = config_from_dict(SpillageConfig, {**data, "output_dir": str(tmp_path / "ray"), "executor": {"backend": "ray", "workers": 2}})
    run_collection(serial, progress=False)
    summary = run_collection(ray_cfg, progress=False)
    assert len(kill_a_worker_mid_episode) == 1
    assert summary["candidates_failed"] == 0
    expected = {p.name: read_episode(p) for p in list_episode_files(serial.output_dir)}
    got = {p.name: read_episode(p) for p in list_episode_files(ray_cfg.output_dir)}
    assert sorted(got) == sorted(expected) and len(got) == 4
    for name, (arrays, meta) in expected.items():
        assert got[name][1] == meta
        for key in arrays:
            np.testing.assert_array_equal(got[name][0][key], arrays[key], err_msg=f"{name}:{key}")
    logged = [json.loads(line)["id"] for line in (Path(ray_cfg.output_dir) / "candidates.jsonl").read_text().splitlines()]
    assert len(logged) == len(set(logged))  # every candidate decided once
