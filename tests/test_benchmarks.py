"""The benchmark runner: every script it names exists and imports, and its summary reads each one's JSON."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _module(name: str):
    spec = importlib.util.spec_from_file_location(f"benchmarks_{name}", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("full", [False, True])
def test_every_benchmark_the_runner_names_is_a_script_that_imports(full, monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))  # as `python benchmarks/NAME.py` runs them: they import each other
    commands = _module("run_all").benchmark_commands(full)
    assert "transfer_ik" in commands
    for name, command in commands.items():
        script = Path(command[1])
        assert command[0] == sys.executable and script.is_file(), name
        _module(script.stem)  # its imports resolve (a stale import breaks the whole run)


def test_the_transfer_ik_benchmark_gets_its_headline_ratios():
    run_all = _module("run_all")
    result = {"wound_wrist": {"refine_fine_over_solve": 9.0, "heading_free_over_solve": 10.4},
              "rest_posture": {"refine_fine_over_solve": 0.4, "heading_free_over_solve": 0.7}}
    rows = dict(run_all.headlines("transfer_ik", result))
    assert rows["transfer IK from the wound wrist: heading_free (x PyBullet's solve)"] == 10.4
    assert len(rows) == 4


def test_the_cluster_plan_takes_rounds_of_episodes_or_the_drivers_serial_time():
    parallel_stage = _module("bench_cluster_plan").parallel_stage
    over = {"dispatch_overhead_per_task_s": 0.5, "driver_cpu_per_task_s": 0.01, "pool_start_up_s": 10.0}
    # 800 episodes of 30 s on 256 cores: 4 rounds of 30.5 s, then start-up
    assert parallel_stage(800, 30.0, 256, over) == {"episodes": 800, "rounds": 4, "wall_s": 132.0, "limited_by": "cores"}
    assert parallel_stage(100, 30.0, 256, over)["limited_by"] == "episodes"
    # a driver needing 1 s per task cannot feed 256 workers of 30 s episodes: its 800 s are the stage
    slow = {**over, "driver_cpu_per_task_s": 1.0}
    assert parallel_stage(800, 30.0, 256, slow) == {"episodes": 800, "rounds": 4, "wall_s": 810.0, "limited_by": "driver"}
