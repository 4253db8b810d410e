"""Evaluation over Ray: two actors, each loading the checkpoints once, give exactly the serial records."""

from __future__ import annotations

import pytest

ray = pytest.importorskip("ray")

from tests.evaluation.eval_helpers import TIMING, eval_config  # noqa: E402
from grits_lab.evaluation.evaluation_run import evaluate  # noqa: E402
from grits_lab.runners.ray_executor import RayExecutor  # noqa: E402

pytestmark = [pytest.mark.ray, pytest.mark.slow]  # about a minute: Ray start-up and four episodes


def test_ray_workers_give_the_serial_records(models, tmp_path):
    methods = ["dp", "grits"]
    serial = evaluate(eval_config(models, tmp_path / "serial", methods=methods, trials=2), progress=False)
    ray.init(address="local", num_cpus=2, include_dashboard=False)
    try:
        with RayExecutor(workers=2) as executor:
            parallel = evaluate(eval_config(models, tmp_path / "ray", methods=methods, trials=2), progress=False, executor=executor)
    finally:
        ray.shutdown()
    assert len(parallel) == 4 and (parallel["error"] == "").all()
    keep = [c for c in serial.columns if c not in TIMING]
    assert serial[keep].equals(parallel[keep])
