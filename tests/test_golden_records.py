"""Golden records: small reference outputs of the current task protocol (tests/artifacts/), replayed
and compared. A change that moves one changes a result: bump the protocol (docs/protocol.md).

Integers, booleans and strings must match exactly; floats within FLOAT_TOLERANCE (cross-CPU float
noise); columns that measure time are left out. Regenerate, after bumping the version, with

    GRITS_LAB_REGENERATE_GOLDEN=1 python -m pytest tests/test_golden_records.py -q
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest

from grits_lab.versions import PROTOCOL, PROTOCOL_VERSION

ARTIFACTS = Path(__file__).parent / "artifacts"
REGENERATE = os.environ.get("GRITS_LAB_REGENERATE_GOLDEN") == "1"
COMMAND = "GRITS_LAB_REGENERATE_GOLDEN=1 python -m pytest tests/test_golden_records.py -q"
FLOAT_TOLERANCE = 1e-6
TIMING = {"wall_time_s", "settle_time_s", "scoop_time_s", "transfer_time_s", "plan_time_mean_s", "plan_time_max_s"}
FOOD, LEVEL, SEED = "chocolate_balls", "low", 3


def _plain(value: Any) -> Any:
    """JSON-able copy: numpy scalars and arrays as Python numbers and lists, NaN as None."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in sorted(value.items()) if k not in TIMING}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in list(value)]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and math.isnan(value):
        return None
    return value


def _differences(golden: Any, now: Any, where: str = "") -> list[str]:
    if isinstance(golden, dict) and isinstance(now, dict):
        out = [f"{where}.{k}: only in the golden record" for k in golden if k not in now]
        out += [f"{where}.{k}: not in the golden record" for k in now if k not in golden]
        return out + [d for k in golden if k in now for d in _differences(golden[k], now[k], f"{where}.{k}")]
    if isinstance(golden, list) and isinstance(now, list):
        if len(golden) != len(now):
            return [f"{where}: {len(golden)} entries in the golden record, {len(now)} now"]
        return [d for i, (g, n) in enumerate(zip(golden, now)) for d in _differences(g, n, f"{where}[{i}]")]
    exact = isinstance(golden, (bool, int, str)) or golden is None or isinstance(now, (bool, str)) or now is None
    if exact and golden != now or not exact and not math.isclose(golden, now, rel_tol=FLOAT_TOLERANCE, abs_tol=FLOAT_TOLERANCE):
        return [f"{where}: {golden!r} in the golden record, {now!r} now"]
    return []


def expert_rollout(tmp_path: Path) -> dict[str, Any]:
    """`grits-lab rollout --expert --json`: the scripted expert's scoop on one seeded world."""
    from grits_lab.sim import ScoopEnv, SimConfig, play_episode

    env = ScoopEnv(SimConfig())
    try:
        record, played = play_episode(env, FOOD, LEVEL, SEED)
    finally:
        env.close()
    return {**record.summary(), "spilled_over_time": record.spilled_over_time, "trajectory_sum": float(played.sum())}


def spillage_trial(tmp_path: Path) -> dict[str, Any]:
    """One spillage trial (shifted expert scoop, no exit): its chunk labels and spilled counts."""
    from grits_lab.collection.jobs import base_trajectory
    from grits_lab.collection.spillage_trials import SpillageConfig, expert_mean_trajectory, make_trial_spec, source_bowl_region
    from grits_lab.config import config_from_dict
    from grits_lab.runners.work import WorkerContext, execute_spec

    np.save(tmp_path / "base.npy", expert_mean_trajectory(SpillageConfig())[:36])
    config = config_from_dict(SpillageConfig, {
        "kind": "spillage", "output_dir": str(tmp_path / "spill"), "episodes": 1, "shapes": ["sphere"], "seed": SEED,
        "base_trajectory": str(tmp_path / "base.npy"), "particles": {"fill_height": [0.01, 0.01], "radius": [0.004, 0.006]},
        "cloud": {"n_points": 64, "cad_surface_samples": 400}, "executor": {"backend": "serial"}, "exit": {"kind": "exit", "enabled": False},
        "sim": {"cameras": [{"name": "front", "eye": [1.05, -0.15, 0.55], "target": [0.5, -0.1, 0.03], "width": 64, "height": 48}]},
    })
    spec = make_trial_spec(config, base_trajectory(config), source_bowl_region(config), "sphere", 0)
    context = WorkerContext()
    try:
        result = execute_spec(spec, context)
    finally:
        context.close()
    assert result.ok, result.traceback
    arrays, meta = result.payload["arrays"], result.payload["meta"]
    labels = {k: arrays[k] for k in arrays if k.startswith(("chunk_spilled", "spilled_")) or k == "chunk_start"}
    return {"meta": {k: v for k, v in meta.items() if not isinstance(v, (dict, list))}, **labels}


def expert_task_episode(tmp_path: Path) -> dict[str, Any]:
    """The whole task with the scripted expert's scoop (the `expert` method): scoop, lift, carry,
    pour, and every spilled particle's stage and cause."""
    from grits_lab.evaluation.controllers import ExpertController
    from grits_lab.evaluation.evaluation_config import EvaluationConfig
    from grits_lab.evaluation.task_episode import run_task_episode
    from grits_lab.perception.env_clouds import builder_for_env
    from grits_lab.sim import ScoopEnv

    config = EvaluationConfig(methods=["expert"], foods=[FOOD], levels=[LEVEL], trials=1)
    env = ScoopEnv(config.sim)
    try:
        record = run_task_episode(env, ExpertController(), config, seed=SEED, food=FOOD, level=LEVEL,
                                  builder=builder_for_env(config.cloud, env))
    finally:
        env.close()
    return {k: v for k, v in record.items() if not k.startswith("_") and k != "renders"}


GOLDEN: dict[str, Callable[[Path], dict[str, Any]]] = {
    "expert_rollout.json": expert_rollout,
    "expert_task_episode.json": expert_task_episode,
    "spillage_trial.json": spillage_trial,
}


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_a_golden_record_is_reproduced(name, tmp_path):
    now = _plain(GOLDEN[name](tmp_path))
    path = ARTIFACTS / name
    if REGENERATE:
        path.write_text(json.dumps({"protocol": PROTOCOL, "record": now}, indent=1, sort_keys=True) + "\n")
        return
    if not path.is_file():
        pytest.skip(f"no golden record {path.name} yet; make it with: {COMMAND}")
    golden = json.loads(path.read_text())
    assert golden["protocol"] == PROTOCOL, (
        f"{name} was made under {golden['protocol']}, this code runs {PROTOCOL}: regenerate it ({COMMAND})")
    differences = _differences(golden["record"], now)
    assert not differences, (
        f"{name} moved ({len(differences)} values, first: {differences[0]}): this change moves results of {PROTOCOL}. "
        f"Bump PROTOCOL_VERSION in grits_lab/versions.py to {PROTOCOL_VERSION + 1}, add scoop-v{PROTOCOL_VERSION + 1} "
        f"to docs/protocol.md, and regenerate: {COMMAND}")
