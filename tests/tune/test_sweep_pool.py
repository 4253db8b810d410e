"""A GRITS sweep keeps one pool of workers for all its trials, and shuts it down at the end, on Ctrl-C and on errors.

Real episodes with the tiny trained checkpoints of tests/evaluation/conftest.py (`models`).
"""

from __future__ import annotations

import os
import shutil
import time

import pandas as pd
import pytest
import yaml

from tests.evaluation.conftest import models  # noqa: F401  (session fixture: tiny trained checkpoints)
from tests.evaluation.eval_helpers import eval_config
from grits_lab.config import config_to_dict
from grits_lab.runners import SerialExecutor
from grits_lab.tune import grits_binding
from grits_lab.tune.job import run_sweep
from grits_lab.tune.study_config import load_study_config


def grits_sweep(sweep_file, models, tmp_path, executor, n_trials=3):  # noqa: F811
    """A sweep file whose trials run GRITS on two episodes with copies of the tiny checkpoints."""
    copies = {}
    for key in ("policy", "predictor"):
        copies[key] = tmp_path / "checkpoints" / f"{key}.pt"
        copies[key].parent.mkdir(exist_ok=True)
        shutil.copy(models[key], copies[key])
    evaluation = eval_config({**models, **{k: str(p) for k, p in copies.items()}}, tmp_path / "unused",
                             methods=["grits"], executor=executor)
    (tmp_path / "evaluate.yaml").write_text(yaml.safe_dump(config_to_dict(evaluation), sort_keys=False))
    path = sweep_file("pool", n_trials=n_trials, evaluator="grits",
                      validation={"foods": ["chocolate_balls"], "levels": ["low"], "trials": 2, "seed": 11},
                      evaluation={"config": str(tmp_path / "evaluate.yaml"), "method": "grits",
                                  "checkpoints": [str(p) for p in copies.values()]})
    return load_study_config(path), copies


class SpyExecutor(SerialExecutor):
    """A serial executor that remembers whether it was closed."""

    def __init__(self):
        super().__init__()
        self.closed = False

    def close(self):
        self.closed = True
        super().close()


@pytest.fixture
def spy_pools(monkeypatch):
    """Every executor the GRITS evaluator makes, in order (serial ones that record their closing)."""
    made = []

    def make(config):
        made.append(SpyExecutor())
        return made[-1]

    monkeypatch.setattr(grits_binding, "make_executor", make)
    return made


def _pid_gone(pid: int, within_s: float) -> bool:
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.2)
    return False


@pytest.mark.ray
def test_three_trials_run_on_one_ray_pool_that_loads_the_checkpoints_once_per_worker(sweep_file, models, tmp_path,  # noqa: F811
                                                                                    monkeypatch):
    ray = pytest.importorskip("ray")
    assert not ray.is_initialized()
    config, copies = grits_sweep(sweep_file, models, tmp_path, {"backend": "ray", "workers": 2, "num_cpus": 2})
    pools, seen = [], []
    make, evaluate = grits_binding.make_executor, grits_binding.evaluate_guidance

    def counted_make(executor_config):
        pools.append(make(executor_config))
        return pools[-1]

    def evaluate_then_remove_checkpoints(*args, executor, **kwargs):
        records = evaluate(*args, executor=executor, **kwargs)
        seen.append((id(executor), sorted(executor.worker_pids())))
        for path in copies.values():  # from now on a worker that loads a checkpoint again fails its episode
            path.unlink(missing_ok=True)
        return records

    monkeypatch.setattr(grits_binding, "make_executor", counted_make)
    monkeypatch.setattr(grits_binding, "evaluate_guidance", evaluate_then_remove_checkpoints)
    summary = run_sweep(config, progress=False, plots=False)
    assert summary["states"] == {"COMPLETE": 3}, summary["states"]
    pids = seen[0][1]
    assert len(pools) == 1 and len(seen) == 3 and len(pids) == 2
    assert all(entry == seen[0] for entry in seen), seen  # the same pool, the same two actor processes
    records = pd.concat([pd.read_parquet(p) for p in sorted((config.study_dir / "records").glob("trial_*.parquet"))])
    assert len(records) == 6 and (records["error"] == "").all(), records["error"].tolist()
    assert records["rho"].nunique() == 3
    # Closed at the end: the Ray this pool started is shut down and its actors are gone.
    assert not ray.is_initialized()
    assert all(_pid_gone(pid, 30) for pid in pids)


def test_a_trial_that_raises_closes_the_pool_and_the_next_trial_starts_a_fresh_one(sweep_file, models, tmp_path,  # noqa: F811
                                                                                   spy_pools, monkeypatch):
    config, _ = grits_sweep(sweep_file, models, tmp_path, {"backend": "serial"})
    evaluator = grits_binding.GritsEvaluator(config)
    handed = []

    def broken(*args, executor, **kwargs):
        handed.append(executor)
        raise RuntimeError("simulator crashed")

    monkeypatch.setattr(grits_binding, "evaluate_guidance", broken)
    with pytest.raises(RuntimeError):
        evaluator(1.0, 30, run_id="t0")
    assert handed == spy_pools[:1] and spy_pools[0].closed

    def fine(*args, executor, **kwargs):
        handed.append(executor)
        return pd.DataFrame()

    monkeypatch.setattr(grits_binding, "evaluate_guidance", fine)
    evaluator(1.0, 30, run_id="t1")
    evaluator(2.0, 12, run_id="t2")
    assert handed[1:] == [spy_pools[1], spy_pools[1]] and len(spy_pools) == 2 and not spy_pools[1].closed
    evaluator.close()
    evaluator.close()  # idempotent
    assert spy_pools[1].closed


def test_ctrl_c_in_a_trial_shuts_the_sweeps_pool_down(sweep_file, models, tmp_path, spy_pools, monkeypatch):  # noqa: F811
    config, _ = grits_sweep(sweep_file, models, tmp_path, {"backend": "serial"})

    def interrupted(*args, executor, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(grits_binding, "evaluate_guidance", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(config, progress=False, plots=False)
    assert len(spy_pools) == 1 and spy_pools[0].closed


def test_two_grits_sweep_processes_each_with_its_pool_share_one_journal_and_its_budget(sweep_file, models, tmp_path):  # noqa: F811
    from tests.tune.test_workers import assert_shared_study, finish, load_trials, start

    config, _ = grits_sweep(sweep_file, models, tmp_path, {"backend": "serial"}, n_trials=4)
    path = tmp_path / f"{config.study_name}.yaml"  # the file grits_sweep wrote; its journal is the default one
    procs = [start(path), start(path)]
    for proc in procs:
        finish(proc, timeout=600)
    assert_shared_study(load_trials(path), 4)
