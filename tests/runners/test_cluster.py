"""A real Ray cluster: `ray start --head` in a subprocess, then a job connects through `address:` as a user would."""

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from tests.tune.conftest import postgres_url, sweep_file  # noqa: F401  (fixtures of the sweep tests)

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


def _doc_block():
    return open(CLUSTER_DOC).read().split("## Scaling out", 1)[1].split("```bash", 1)[1].split("```", 1)[0]


def _commands(lines):
    return [line.split("#", 1)[0].strip() for line in lines if line.split("#", 1)[0].strip()]


def _cluster_steps():
    """docs/cluster.md's "Scaling out" step 1 (commands) and step 2's environment, as a user reads them."""
    text = _doc_block()
    step1 = text.split("# 1.", 1)[1].split("# 2.", 1)[0].splitlines()[1:]
    exports = [line for line in text.split("# 2.", 1)[1].splitlines() if line.startswith("export ")]
    env = dict(item.split("=", 1) for line in exports for item in line.split()[1:])
    return _commands(step1), env


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


@contextlib.contextmanager
def _documented_nodes():
    """A head and a worker node on this machine, started with the step-1 commands of docs/cluster.md as written,
    from a fresh HOME (no ~/.ray/auth_token, no earlier run): the head given a free port, 1 CPU and its own temp
    dir, the worker 2 CPUs. Yields a namespace: address, env (step 2's exports applied), home, the head's and the
    worker's process groups, and the log of every command run."""
    import tempfile
    from types import SimpleNamespace

    commands, env_vars = _cluster_steps()
    port = _free_port()
    temp_dir = tempfile.mkdtemp(prefix="rn", dir="/tmp")  # short: Ray's socket paths must fit 107 bytes
    home = tempfile.mkdtemp(prefix="home", dir="/tmp")
    groups, log = {}, []
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0", HOME=home)
    env.pop("RAY_AUTH_MODE", None)  # the doc's lines say where it is needed
    env.pop("RAY_AUTH_TOKEN", None)
    try:
        for command in commands:
            line = command.replace("HEAD_IP", "127.0.0.1").replace("6379", str(port))
            role = None
            if "--head" in line:
                line, role = line + f" --num-cpus=1 --include-dashboard=false --disable-usage-stats --temp-dir={temp_dir}", "head"
            elif "ray start" in line:
                line, role = line + " --num-cpus=2 --disable-usage-stats", "worker"
            proc = subprocess.Popen(["bash", "-c", line], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
            out, _ = proc.communicate(timeout=120)
            groups[role or f"step{len(log)}"] = proc.pid
            shown = "(the token, not shown)" if "auth-token" in line else (out.decode().strip().splitlines() or [""])[-1]
            log.append(f"$ {line}\n{shown}")
            assert proc.returncode == 0, f"docs/cluster.md step 1 failed: {line}\n{out.decode()[-2000:]}"
        client_env = dict(env, **{k: v.replace("HEAD_IP", "127.0.0.1").replace("6379", str(port)) for k, v in env_vars.items()})
        _wait_for_cpus(f"127.0.0.1:{port}", client_env, 3)
        yield SimpleNamespace(address=f"127.0.0.1:{port}", env=client_env, home=home, head_group=groups["head"],
                              worker_group=groups["worker"], log=log)
    finally:
        for group in reversed(list(groups.values())):
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
        subprocess.run(["rm", "-rf", temp_dir, home])


@pytest.fixture
def two_nodes():
    """docs/cluster.md's two nodes (`_documented_nodes`). Yields (address, env, worker pgid)."""
    with _documented_nodes() as nodes:
        yield nodes.address, nodes.env, nodes.worker_group


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


def _step_commands(number):
    """The commands of step `number` of docs/cluster.md's "Scaling out" block (no exports, no comments)."""
    text = _doc_block().split(f"# {number}.", 1)[1].split(f"# {number + 1}.", 1)[0]
    return [c for c in _commands(text.splitlines()[1:]) if not c.startswith("export ")]


def _run_on_both_nodes(command, nodes, timeout_s=400):
    """Run `command` (bash) with step 2's environment; return (process, the nodes that ran a trial while it ran)."""
    proc = subprocess.Popen(["bash", "-c", command], env=nodes.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen, deadline = set(), time.monotonic() + timeout_s
    while proc.poll() is None and time.monotonic() < deadline:
        seen |= {name for name, group in (("head", nodes.head_group), ("worker", nodes.worker_group))
                 if name not in seen and _node_runs_a_trial(group)}
        time.sleep(0.05)
    out, err = proc.communicate(timeout=max(1.0, deadline - time.monotonic()))
    return proc, out, err, seen


@pytest.mark.postgres
def test_the_cluster_steps_run_as_written_from_a_fresh_home(tmp_path, postgres_url, sweep_file):
    """docs/cluster.md steps 1 to 3 as a new cluster user types them, on a HOME with no Ray token: the head
    authenticates with the token step 1 made, a collection and an evaluation run trials on both nodes, and
    two sweep processes share one PostgreSQL study. The paper's configs are swapped for small ones and the
    pipeline line (hours of training) is left out; everything else is the doc's text."""
    import yaml

    from tests.tune.test_workers import assert_shared_study, load_trials

    small_configs = {
        "experiments/spillage_paper.yaml": _collect_config(tmp_path, None, episodes=6),
        "experiments/evaluate_paper.yaml": tmp_path / "evaluate.yaml",
    }
    small_configs["experiments/evaluate_paper.yaml"].write_text(yaml.safe_dump({
        "run_id": "cluster", "output_dir": str(tmp_path / "evaluate"), "methods": ["rule_based"],
        "foods": ["chocolate_balls"], "levels": ["low"], "trials": 6, "cloud": {"n_points": 64, "cad_surface_samples": 400},
        "scoop": {"max_steps": 36, "min_steps": 12}, "transfer": {"pour_steps": 8, "settle_steps": 5},
    }))
    step2, step3 = _step_commands(2), _step_commands(3)
    assert [c.split()[1] for c in step2] == ["collect", "evaluate", "pipeline"], step2
    with _documented_nodes() as nodes:
        assert os.path.getsize(os.path.join(nodes.home, ".ray", "auth_token")) > 0  # made by step 1, in the fresh HOME
        unauthenticated = dict(nodes.env, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN="0" * 32)
        refused = subprocess.run(["ray", "status", f"--address={nodes.address}"], env=unauthenticated,
                                 capture_output=True, text=True, timeout=120)
        assert refused.returncode != 0, "the head started by step 1 accepts any token"
        for command in step2[:2]:
            config = command.split()[2]
            proc, out, err, seen = _run_on_both_nodes(command.replace(config, str(small_configs[config])) + " --no-progress", nodes)
            nodes.log.append(f"$ {command}  [{small_configs[config].name}]\nexit {proc.returncode}, trials ran on: {sorted(seen)}")
            assert proc.returncode == 0, err[-3000:]
            assert seen == {"head", "worker"}, f"{command}: trials ran only on {seen}\n{err[-2000:]}"
        assert len(list((tmp_path / "spill" / "episodes").glob("*.npz"))) == 6
        import pandas as pd

        records = pd.read_parquet(tmp_path / "evaluate" / "episodes.parquet")
        assert len(records) == 6 and (records["error"].fillna("") == "").all(), records["error"].tolist()

    # step 3 against a throwaway PostgreSQL server; createdb reads the server from libpq's environment
    url = postgres_url.rsplit("/", 1)[0]  # postgresql://postgres@127.0.0.1:PORT
    host, port = url.split("@", 1)[1].split(":")
    pg_env = dict(os.environ, PGHOST=host, PGPORT=port, PGUSER="postgres")
    createdb, sweep = step3[0], step3[1]
    assert createdb == "createdb grits" and sweep.startswith("grits-lab sweep sweeps/grits_paper.yaml --storage postgresql://")
    done = subprocess.run(["bash", "-c", createdb], env=pg_env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    config = sweep_file("cluster_pg", n_trials=8, synthetic={"seconds_per_episode": 0.04})
    storage = f"{url}/grits"
    line = sweep.replace("sweeps/grits_paper.yaml", str(config)).replace("postgresql://USER:PASSWORD@DB_HOST/grits", storage)
    procs = [subprocess.Popen(["bash", "-c", line], env=pg_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
             for _ in range(2)]
    for proc in procs:
        out, _ = proc.communicate(timeout=300)
        assert proc.returncode == 0, out[-3000:]
    assert_shared_study(load_trials(config, storage), 8)
    nodes.log.append(f"$ {createdb}\n$ {sweep}  x2  [{config.name}]\n8 trials shared by 2 processes")
    print("\n".join(nodes.log))
