"""Real processes on one storage: a killed sweep resumes with its history intact, and workers share a study.

Storage shared by separate `grits-lab sweep` processes: the journal file, and a real PostgreSQL
server started by the test session (skipped with the reason where it cannot start).
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest
from optuna.trial import TrialState
from tests.tune.sweep_helpers import REPO, sweep_command

from grits_lab.tune.study_config import load_study_config
from grits_lab.tune.storage import open_storage
from grits_lab.tune.study import REQUEUED_ATTR, RETRY_OF_ATTR, WORKER_ATTR


def load_trials(config_path, storage_spec=None):
    import optuna

    config = load_study_config(config_path)
    storage, _ = open_storage(storage_spec or config.storage, config.study_dir / "journal.log")
    return optuna.load_study(study_name=config.study_name, storage=storage).get_trials(deepcopy=True)


def start(config, *extra):
    return subprocess.Popen(sweep_command(config, *extra), cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def finish(proc, timeout=120):
    out, _ = proc.communicate(timeout=timeout)
    assert proc.returncode == 0, out
    return out


def test_killed_sweep_resumes_with_history_intact(sweep_file):
    config = sweep_file("killed", n_trials=5, synthetic={"seconds_per_episode": 0.05})
    proc = start(config)
    deadline = time.monotonic() + 60
    try:
        while True:  # kill the sweep in the middle of a trial, after two complete ones
            assert time.monotonic() < deadline, "the sweep made no progress"
            if (config.parent / "results" / "killed" / "journal.log").exists():
                trials = load_trials(config)
                complete = sum(t.state == TrialState.COMPLETE for t in trials)
                if complete >= 2 and any(t.state == TrialState.RUNNING and t.params for t in trials):
                    break
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    before = [t for t in load_trials(config) if t.state == TrialState.COMPLETE]
    orphans = [t for t in load_trials(config) if t.state == TrialState.RUNNING]
    assert len(orphans) == 1
    finish(start(config))
    after = load_trials(config)
    by_number = {t.number: t for t in after}
    for t in before:  # completed history untouched
        kept = by_number[t.number]
        assert (kept.state, kept.params, kept.values) == (t.state, t.params, t.values)
    orphan = by_number[orphans[0].number]
    assert orphan.state == TrialState.FAIL and orphan.user_attrs[REQUEUED_ATTR] is True
    retries = [t for t in after if t.user_attrs.get(RETRY_OF_ATTR) == orphan.number]
    assert len(retries) == 1 and retries[0].state == TrialState.COMPLETE
    assert retries[0].params == orphan.params
    assert sum(t.state == TrialState.COMPLETE for t in after) == 5
    assert after[0].params == {"rho": 2.5, "s": 30}


def assert_shared_study(trials, n_trials):
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    # Two workers may each start one trial when one slot is left: at most one extra.
    assert n_trials <= len(complete) <= n_trials + 1
    assert not [t for t in trials if t.state != TrialState.COMPLETE]
    points = [(round(t.params["rho"], 9), t.params["s"]) for t in complete]
    assert len(set(points)) == len(points), "workers repeated each other's points"
    assert points.count((2.5, 30)) == 1
    workers = {t.user_attrs[WORKER_ATTR].rsplit(":", 2)[1] for t in complete}
    assert len(workers) == 2, "both workers should have run trials"


def test_two_processes_share_one_journal_file(sweep_file, tmp_path):
    journal = tmp_path / "shared" / "journal.log"
    config = sweep_file("shared_journal", n_trials=8, storage=str(journal),
                        synthetic={"seconds_per_episode": 0.04})
    procs = [start(config), start(config)]
    for proc in procs:
        finish(proc)
    assert_shared_study(load_trials(config), 8)


@pytest.mark.postgres
def test_two_processes_share_one_postgresql_study(sweep_file, postgres_url):
    config = sweep_file("shared_pg", n_trials=8, synthetic={"seconds_per_episode": 0.04})
    procs = [start(config, "--storage", postgres_url), start(config, "--storage", postgres_url)]
    for proc in procs:
        finish(proc)
    assert_shared_study(load_trials(config, postgres_url), 8)
