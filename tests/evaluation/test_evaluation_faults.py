"""Evaluation under a lost worker: the killed episode is re-run from its seed, nothing lost or duplicated."""

from __future__ import annotations

import pytest

ray = pytest.importorskip("ray")

from tests.evaluation.eval_helpers import TIMING, eval_config  # noqa: E402
from grits_lab.evaluation.evaluation_run import evaluate  # noqa: E402

pytestmark = pytest.mark.ray


def test_a_worker_killed_during_evaluate_loses_and_duplicates_nothing(models, tmp_path, kill_a_worker_mid_episode):
    serial = evaluate(eval_config(models, tmp_path / "serial", methods=["rule_based"], trials=3), progress=False)
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    try:
        config = eval_config(models, tmp_path / "ray", methods=["rule_based"], trials=3, executor={"backend": "ray", "workers": 2})
        parallel = evaluate(config, progress=False)
    finally:
        ray.shutdown()
    assert len(kill_a_worker_mid_episode) == 1
    key = ["method", "food", "level", "trial"]
    assert len(parallel) == 3 and not parallel.duplicated(key).any() and (parallel["error"] == "").all()
    keep = [c for c in serial.columns if c not in TIMING]
    assert serial[keep].sort_values(key).reset_index(drop=True).equals(parallel[keep].sort_values(key).reset_index(drop=True))
