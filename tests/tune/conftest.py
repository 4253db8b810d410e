"""Fixtures for the sweep tests: small synthetic sweep files and a throwaway PostgreSQL server."""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest
import yaml
from tests.tune.sweep_helpers import free_port


@pytest.fixture
def sweep_file(tmp_path):
    """Write a synthetic sweep file under tmp_path; keyword overrides merge into the mapping."""

    def write(name: str = "study", **overrides) -> Path:
        data = {
            "study_name": name,
            "n_trials": 6,
            "evaluator": "synthetic",
            "rho": {"low": 0.5, "high": 8.0, "log": True},
            "s": {"low": 0, "high": 90, "step": 6},
            "enqueue": [{"rho": 2.5, "s": 30}],
            "objective": {"mode": "single", "spillage_weight": 1.0},
            "sampler": {"name": "tpe", "seed": 3, "n_startup_trials": 3},
            "validation": {"foods": ["soybeans", "dried_jujube"], "levels": ["low", "high"], "trials": 2,
                           "seed": 11},
            "output_dir": str(tmp_path / "results"),
        }
        for key, value in overrides.items():
            if isinstance(value, dict) and isinstance(data.get(key), dict):
                data[key] = {**data[key], **value}
            else:
                data[key] = value
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        return path

    return write


def _postgres_binaries() -> tuple[str, str] | None:
    candidates = sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=lambda p: int(p.split("/")[-2]) if p.split("/")[-2].isdigit() else 0)
    for directory in [os.path.dirname(shutil.which("initdb") or "")] + candidates[::-1]:
        initdb, pg_ctl = os.path.join(directory, "initdb"), os.path.join(directory, "pg_ctl")
        if directory and os.access(initdb, os.X_OK) and os.access(pg_ctl, os.X_OK):
            return initdb, pg_ctl
    return None


@pytest.fixture(scope="session")
def postgres_url():
    """A real PostgreSQL server in a temporary directory on a free port, for the whole session.

    PostgreSQL refuses to run as root, so under root the server runs as `nobody` (via runuser).
    Skips, with the reason, where the binaries are missing or the server cannot start.
    """
    binaries = _postgres_binaries()
    if binaries is None:
        pytest.skip("PostgreSQL server binaries (initdb, pg_ctl) not found: install Debian's postgresql package")
    initdb, pg_ctl = binaries
    try:
        import psycopg2
    except ImportError:
        pytest.skip("psycopg2 is not installed (pip install -e '.[test]')")
    prefix: list[str] = []
    root = Path(tempfile.mkdtemp(prefix="grits-pg-"))
    if os.geteuid() == 0:
        runuser = shutil.which("runuser")
        if runuser is None:
            shutil.rmtree(root, ignore_errors=True)
            pytest.skip("running as root and `runuser` is missing: PostgreSQL cannot run as root")
        user = pwd.getpwnam("nobody")
        os.chown(root, user.pw_uid, user.pw_gid)
        prefix = [runuser, "-u", "nobody", "--"]
    data, port = root / "data", free_port()

    def run(args: list[str]) -> subprocess.CompletedProcess:
        return subprocess.run(prefix + args, cwd=root, capture_output=True, text=True, timeout=60)

    started = False
    try:
        init = run([initdb, "-D", str(data), "-U", "postgres", "-A", "trust", "-E", "UTF8", "--no-sync"])
        if init.returncode != 0:
            pytest.skip(f"initdb failed: {(init.stderr or init.stdout).strip().splitlines()[-1:]}")
        options = f"-p {port} -k {root} -c listen_addresses=127.0.0.1 -c fsync=off -c max_connections=50"
        start = run([pg_ctl, "-D", str(data), "-o", options, "-l", str(root / "server.log"), "-w", "-t", "30", "start"])
        if start.returncode != 0:
            log = (root / "server.log").read_text() if (root / "server.log").exists() else start.stderr
            pytest.skip(f"PostgreSQL did not start: {log.strip().splitlines()[-1:]}")
        started = True
        connection = psycopg2.connect(host="127.0.0.1", port=port, user="postgres", dbname="postgres")
        connection.autocommit = True
        with connection.cursor() as cursor:
            cursor.execute("CREATE DATABASE grits_sweeps")
        connection.close()
        yield f"postgresql://postgres@127.0.0.1:{port}/grits_sweeps"
    finally:
        if started:
            run([pg_ctl, "-D", str(data), "-m", "immediate", "stop"])
        shutil.rmtree(root, ignore_errors=True)
