"""A real Ray cluster: `ray start --head` in a subprocess, then a job connects through `address:` as a user would."""

import os
import signal
import socket
import subprocess
import sys
import time

import pytest

pytestmark = [pytest.mark.cluster, pytest.mark.ray]


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def ray_head():
    port = _free_port()
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0")
    # start_new_session: every daemon `ray start` spawns stays in this process group, so teardown
    # stops exactly this cluster and nothing else running on the machine.
    proc = subprocess.Popen(
        ["ray", "start", "--head", f"--port={port}", "--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
    )
    out, _ = proc.communicate(timeout=120)
    if proc.returncode != 0:
        pytest.fail(f"ray start failed:\n{out.decode()[-2000:]}")
    try:
        yield f"127.0.0.1:{port}"
    finally:
        # `ray start` records the head's address for later `ray.init()` calls; drop our entry
        # so that nothing tries to connect to this cluster after it is gone.
        current = "/tmp/ray/ray_current_cluster"
        try:
            with open(current) as fh:
                if fh.read().strip().endswith(f":{port}"):
                    os.remove(current)
        except OSError:
            pass
        for sig in (signal.SIGTERM, signal.SIGKILL):
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                break
            time.sleep(2)


def _run(code, address, timeout=300):
    # Recent Ray starts clusters with token authentication; a client opts in with RAY_AUTH_MODE.
    env = dict(os.environ, RAY_AUTH_MODE="token", RAY_USAGE_STATS_ENABLED="0")
    return subprocess.run([sys.executable, "-c", code.replace("ADDRESS", address)], env=env, capture_output=True, text=True, timeout=timeout)


def test_executor_connects_through_address_and_runs_on_cluster_workers(ray_head):
    code = """
import json, ray
from grits_lab.runners import EpisodeSpec, ExecutorConfig, make_executor, SerialExecutor, probe_episode
specs = [EpisodeSpec(f"e{i}", probe_episode, seed=i) for i in range(6)]
with make_executor(ExecutorConfig(address="ADDRESS")) as ex:
    n = ex.num_workers
    res = {r.episode_id: r.payload for r in ex.map_unordered(specs)}
    nodes = len(ray.nodes())
with SerialExecutor() as ex:
    ref = {r.episode_id: r.payload for r in ex.map_unordered(specs)}
print(json.dumps({"workers": n, "same": res == ref, "nodes": nodes, "count": len(res)}))
"""
    proc = _run(code, ray_head)
    assert proc.returncode == 0, proc.stderr[-3000:]
    import json

    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out == {"workers": 2, "same": True, "nodes": 1, "count": 6}


def test_collection_runs_unchanged_on_the_cluster(ray_head, tmp_path):
    """`grits-lab collect` with `executor.address:` set, as a cluster user runs it."""
    import json

    import yaml

    config = {
        "kind": "spillage", "output_dir": str(tmp_path / "spill"), "episodes": 2, "spill_fraction": 0.0, "shapes": ["sphere"],
        "particles": {"fill_height": [0.005, 0.005]}, "cloud": {"n_points": 64, "cad_surface_samples": 500},
        "sim": {"cameras": [{"name": "front", "eye": [1.05, -0.15, 0.55], "target": [0.5, -0.1, 0.03], "width": 64, "height": 48}]},
        "executor": {"address": ray_head},
    }
    path = tmp_path / "cluster.yaml"
    path.write_text(yaml.safe_dump(config))
    env = dict(os.environ, RAY_AUTH_MODE="token", RAY_USAGE_STATS_ENABLED="0")
    proc = subprocess.run(["grits-lab", "collect", str(path), "--no-progress"], env=env, capture_output=True, text=True, timeout=400)
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = json.loads(proc.stdout[proc.stdout.index("{"):])
    assert summary["episodes"] == 2 and summary["buckets"] == {"sphere/0": 2, "sphere/1": 0}
    assert len(list((tmp_path / "spill" / "episodes").glob("*.npz"))) == 2


def test_client_without_token_gets_one_clear_error(ray_head):
    code = """
from grits_lab.errors import GritsError
from grits_lab.runners import ExecutorConfig, make_executor
try:
    make_executor(ExecutorConfig(address="ADDRESS"))
except GritsError as exc:
    print("ERR", exc)
"""
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0")
    env.pop("RAY_AUTH_MODE", None)
    proc = subprocess.run([sys.executable, "-c", code.replace("ADDRESS", ray_head)], env=env, capture_output=True, text=True, timeout=200)
    assert f"ERR the Ray cluster at {ray_head} requires token authentication" in proc.stdout, proc.stdout + proc.stderr[-2000:]
