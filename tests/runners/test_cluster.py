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


def _collect_config(tmp_path, address, episodes=2):
    import yaml

    config = {
        "kind": "spillage", "output_dir": str(tmp_path / "spill"), "episodes": episodes, "spill_fraction": 0.0, "shapes": ["sphere"],
        "particles": {"fill_height": [0.005, 0.005]}, "cloud": {"n_points": 64, "cad_surface_samples": 500},
        "sim": {"cameras": [{"name": "front", "eye": [1.05, -0.15, 0.55], "target": [0.5, -0.1, 0.03], "width": 64, "height": 48}]},
        "executor": {"address": address},
    }
    path = tmp_path / "cluster.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


@pytest.mark.parametrize("token, says", [
    (None, "requires token authentication and this client sent no token"),
    ("0123456789abcdef0123456789abcdef", "rejected the token from RAY_AUTH_TOKEN: it is not this cluster's token"),
])
def test_a_missing_or_wrong_token_is_refused_in_one_line_before_the_dataset_exists(ray_head, tmp_path, token, says):
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0")
    env.pop("RAY_AUTH_MODE", None)
    if token is not None:
        env.update(RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token)
    proc = subprocess.run(["grits-lab", "collect", str(_collect_config(tmp_path, ray_head)), "--no-progress"],
                          env=env, capture_output=True, text=True, timeout=200)
    err = [line for line in proc.stderr.strip().splitlines() if not line.startswith("pybullet build time")]  # printed by its import
    assert proc.returncode == 2 and len(err) == 1 and says in err[0], proc.stderr[-2000:]
    assert not (tmp_path / "spill").exists()


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


CLUSTER_DOC = os.path.join(os.path.dirname(__file__), "..", "..", "docs", "cluster.md")


def _cluster_steps():
    """docs/cluster.md's "Scaling out" step 1 (commands) and step 2's environment, as a user reads them."""
    text = open(CLUSTER_DOC).read().split("## Scaling out", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    step1 = text.split("# 1.", 1)[1].split("# 2.", 1)[0].splitlines()[1:]
    commands = [line.split("#", 1)[0].strip() for line in step1 if line.split("#", 1)[0].strip()]
    exports = [line for line in text.split("# 2.", 1)[1].splitlines() if line.startswith("export ")]
    env = dict(item.split("=", 1) for line in exports for item in line.split()[1:])
    return commands, env


def _wait_for_cpus(address, env, cpus, timeout_s=120):
    """Block until the cluster at `address` shows `cpus` CPUs: `ray start` on a worker node returns before
    the head counts its CPUs on a busy machine, and a job started then sizes its pool to the head alone."""
    code = (
        "import sys, time, ray\n"
        f"ray.init(address={address!r}, logging_level='ERROR')\n"
        f"deadline = time.monotonic() + {timeout_s}\n"
        f"while ray.cluster_resources().get('CPU', 0) < {cpus} and time.monotonic() < deadline:\n"
        "    time.sleep(0.5)\n"
        "print(ray.cluster_resources().get('CPU', 0))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=timeout_s + 60)
    shown = proc.stdout.strip().splitlines()[-1:] or ["none"]
    assert proc.returncode == 0 and float(shown[0]) >= cpus, f"the cluster shows {shown[0]} CPUs, not {cpus}\n{proc.stderr[-2000:]}"


@pytest.fixture
def two_nodes(tmp_path):
    """A head and a worker node on this machine, started with the step-1 commands of docs/cluster.md as written
    (the head given a free port, 1 CPU, its own temp dir; the worker 2 CPUs). Yields (address, env, worker pgid)."""
    import tempfile

    commands, env_vars = _cluster_steps()
    port = _free_port()
    temp_dir = tempfile.mkdtemp(prefix="rn", dir="/tmp")  # short: Ray's socket paths must fit 107 bytes
    groups, env = [], dict(os.environ, RAY_USAGE_STATS_ENABLED="0")
    env.pop("RAY_AUTH_MODE", None)  # the doc's lines say where it is needed
    try:
        for command in commands:
            line = command.replace("HEAD_IP", "127.0.0.1").replace("6379", str(port))
            if "--head" in line:
                line += f" --num-cpus=1 --include-dashboard=false --disable-usage-stats --temp-dir={temp_dir}"
            elif "ray start" in line:
                line += " --num-cpus=2 --disable-usage-stats"
            proc = subprocess.Popen(["bash", "-c", line], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
            out, _ = proc.communicate(timeout=120)
            groups.append(proc.pid)
            assert proc.returncode == 0, f"docs/cluster.md step 1 failed: {line}\n{out.decode()[-2000:]}"
        client_env = dict(env, **{k: v.replace("HEAD_IP", "127.0.0.1").replace("6379", str(port)) for k, v in env_vars.items()})
        _wait_for_cpus(f"127.0.0.1:{port}", client_env, 3)
        yield f"127.0.0.1:{port}", client_env, groups[-1]
    finally:
        for group in reversed(groups):
            for sig in (signal.SIGTERM, signal.SIGKILL):
                try:
                    os.killpg(group, sig)
                except ProcessLookupError:
                    break
                time.sleep(1)
        try:
            with open("/tmp/ray/ray_current_cluster") as fh:
                if fh.read().strip().endswith(f":{port}"):
                    os.remove("/tmp/ray/ray_current_cluster")
        except OSError:
            pass
        subprocess.run(["rm", "-rf", temp_dir])


def _node_runs_a_trial(group: int) -> bool:
    """Whether an actor process of the node whose daemons are in process group `group` (its raylet is
    the actors' parent) runs a trial now: Ray titles it `ray::_EpisodeWorker.run` while it does."""
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/cmdline", "rb") as fh:
                title = fh.read()
            if b"_EpisodeWorker.run" not in title:
                continue
            with open(f"/proc/{entry.name}/stat") as fh:
                parent = int(fh.read().rsplit(")", 1)[1].split()[1])
            if os.getpgid(parent) == group:
                return True
        except (OSError, ValueError, IndexError):  # the process ended while being read
            continue
    return False


def test_a_collection_finishes_when_a_node_is_lost_following_the_readme_steps(two_nodes, tmp_path):
    """The field's case: `grits-lab collect` of 16 spillage trials on two nodes, the second node killed
    mid-way: the lost trial is re-run on the head's worker and the job ends, in bounded time."""
    address, env, worker_group = two_nodes
    assert env["RAY_AUTH_MODE"] == "token" and env["RAY_ADDRESS"] == address
    config = _collect_config(tmp_path, None, episodes=16)
    text = config.read_text().replace("address: null", "address: null\n  replace_timeout_s: 5")
    config.write_text(text)
    started = time.monotonic()
    proc = subprocess.Popen(["grits-lab", "collect", str(config), "--no-progress"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    episodes = tmp_path / "spill" / "episodes"
    # mid-way, and while the node holds a trial: a node killed between trials loses nothing to re-run
    while proc.poll() is None and (len(list(episodes.glob("*.npz"))) < 3 or not _node_runs_a_trial(worker_group)):
        time.sleep(0.05)
    os.killpg(worker_group, signal.SIGKILL)  # the worker node's raylet and its agents
    killed_at = time.monotonic()
    try:
        out, err = proc.communicate(timeout=150)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err[-3000:]
    assert len(list(episodes.glob("*.npz"))) == 16
    after_kill = time.monotonic() - killed_at
    print(f"killed after {killed_at - started:.1f} s, finished {after_kill:.1f} s later")
    assert "re-running it from its seed" in err, err[-3000:]
    # The pool gives the lost node's two replacements up after replace_timeout_s (5 s here) and says so in
    # one line; on a busy machine the live worker may finish the last trials first, and then there is nothing to say.
    if "not replaced (" in err:
        lines = [line for line in err.splitlines() if "not replaced (" in line]
        assert len(lines) == 1 and lines[0].endswith("continuing with 1 worker"), err[-3000:]
    else:
        assert after_kill < 5 + 30, err[-3000:]
    assert after_kill < 120  # bounded: the job never waits on a worker the cluster cannot place
