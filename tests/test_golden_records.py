"""Golden records: small reference outputs of the current task protocol (tests/artifacts/), replayed
and compared. A change that moves one changes a result: bump the protocol (docs/protocol.md).

Integers, booleans and strings must match exactly; floats within FLOAT_TOLERANCE (cross-CPU float
noise), or within CHAOTIC_TOLERANCE for the columns that amplify that noise; columns that measure
time are left out. NumPy and OpenBLAS pick their SIMD kernels by CPU, so the arm's commands can
differ by ~1e-12 between machines; contact turns that into particle positions a fraction of a
millimetre apart. Measured between the machine that made the records and an AVX2-only AMD EPYC on
`expert_task_episode` (every integer equal, scoop_max_joint_speed_ratio 2.7e-12 relative):
carry_peak_speed_mps 2.9e-5 relative, carry_peak_spoon_accel_mps2 (a second difference) 8.3e-4,
spoon_coverage (cells of a 1 mm grid under the particles' footprints) 2.0e-2, ten cells of 1249. Regenerate, after bumping the version, with

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
FLOAT_TOLERANCE = 1e-4
CHAOTIC_TOLERANCE = {"spoon_coverage": 0.05, "carry_peak_spoon_accel_mps2": 0.01}
# Columns that measure time or name the machine's CPU kernels: they differ between machines by design.
TIMING = {"wall_time_s", "settle_time_s", "scoop_time_s", "transfer_time_s", "plan_time_mean_s", "plan_time_max_s", "cpu_kernels"}
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
    tolerance = CHAOTIC_TOLERANCE.get(where.rsplit(".", 1)[-1], FLOAT_TOLERANCE)
    if exact and golden != now or not exact and not math.isclose(golden, now, rel_tol=tolerance, abs_tol=FLOAT_TOLERANCE):
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


class _Millimetre:
    """A controller whose actions are rounded to 1 mm (1e-3 in the rotation's 6D columns): the
    network's float32 arithmetic may differ by ~1e-7 between CPUs, and the rounding keeps that
    noise out of the simulation, so the record pins the evaluation pipeline, not the CPU."""

    def __init__(self, inner: Any) -> None:
        self._inner = inner

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)

    def plan(self, history: Any, scene: Any) -> Any:
        chunk = self._inner.plan(history, scene)
        if chunk is not None:
            chunk.actions = np.round(chunk.actions.astype(np.float64), 3).astype(np.float32)
            if chunk.unguided_actions is not None:
                chunk.unguided_actions = np.round(chunk.unguided_actions.astype(np.float64), 3).astype(np.float32)
        return chunk


def tiny_policy_task_episode(tmp_path: Path) -> dict[str, Any]:
    """One evaluation episode of the `dp` method with a tiny diffusion policy (seeded initial weights,
    one training step on four expert demonstrations): demonstration windows and normalizers, the
    checkpoint, observation history, DDIM sampling, receding-horizon chunks, the scoop's end and the
    record's columns. A policy this small does not scoop (most of its poses are IK failures), so the
    transfer is pinned by expert_task_episode. Perturbing its weights by 1e-6 leaves the record equal."""
    import torch

    from grits_lab.config import config_from_dict
    from grits_lab.evaluation.evaluation_config import EvaluationConfig
    from grits_lab.evaluation.methods import build_controller
    from grits_lab.evaluation.task_episode import run_task_episode
    from grits_lab.perception.env_clouds import builder_for_env
    from grits_lab.policies.diffusion.training_diffusion import PolicyTrainConfig, train_policy
    from grits_lab.sim import ScoopEnv
    from tests.evaluation.conftest import write_demos

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        demos = write_demos(tmp_path / "demos")
        train_policy(config_from_dict(PolicyTrainConfig, {
            "dataset": str(demos), "output_dir": str(tmp_path / "dp"), "batch_size": 4, "max_steps": 1, "lr": 1e-4,
            "warmup_steps": 0, "val_fraction": 0.0, "log_every": 1, "checkpoint_every": 1, "num_threads": 1, "seed": 0,
            "cache_points_per_object": 32,
            "policy": {"horizon": 16, "n_obs_steps": 2, "n_action_steps": 12,
                       "obs_encoder": {"kind": "pointcloud", "points_per_object": 16, "point_hidden": [16], "feature_dim": 8, "cloud_steps": 1},
                       "unet": {"down_dims": [16, 32], "kernel_size": 3, "n_groups": 4, "diffusion_step_embed_dim": 16}},
        }), progress=False)
        config = config_from_dict(EvaluationConfig, {
            "methods": ["dp"], "foods": [FOOD], "levels": [LEVEL], "trials": 1,
            "scoop": {"max_steps": 36, "min_steps": 12}, "cloud": {"n_points": 32, "cad_surface_samples": 400}})
        paths = {"policy": str(tmp_path / "dp" / "checkpoints" / "last.pt")}
        controller = _Millimetre(build_controller("dp", config, paths, lambda key, factory: factory()))
        env = ScoopEnv(config.sim)
        try:
            record = run_task_episode(env, controller, config, seed=SEED, food=FOOD, level=LEVEL,
                                      builder=builder_for_env(config.cloud, env))
        finally:
            env.close()
    finally:
        torch.set_num_threads(threads)
    return {k: v for k, v in record.items() if not k.startswith("_") and k != "renders"}


GOLDEN: dict[str, Callable[[Path], dict[str, Any]]] = {
    "expert_rollout.json": expert_rollout,
    "expert_task_episode.json": expert_task_episode,
    "spillage_trial.json": spillage_trial,
    "tiny_policy_task_episode.json": tiny_policy_task_episode,
}


def test_the_comparison_forgives_cpu_noise_and_nothing_larger():
    golden = {"spilled": 3, "carry_peak_speed_mps": 0.1182731, "spoon_coverage": 0.4083, "ok": True}
    assert _differences(golden, {**golden, "carry_peak_speed_mps": 0.1182765, "spoon_coverage": 0.4003}) == []
    assert _differences(golden, {**golden, "spilled": 4}) == [".spilled: 3 in the golden record, 4 now"]
    assert len(_differences(golden, {**golden, "carry_peak_speed_mps": 0.1192})) == 1  # 0.8 %: a moved result
    assert len(_differences(golden, {**golden, "spoon_coverage": 0.36})) == 1  # 12 %: a different scoop
    assert len(_differences(golden, {**golden, "ok": False})) == 1


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
    added = [d for d in differences if d.endswith(": not in the golden record")]
    assert len(added) < len(differences) or not added, (
        f"{name} gained {len(added)} columns ({', '.join(d.split(':')[0] for d in added)}) beside unchanged values: "
        f"a new column keeps {PROTOCOL} (docs/protocol.md); regenerate: {COMMAND}")
    assert not differences, (
        f"{name} moved ({len(differences)} values, first: {differences[0]}): this change moves results of {PROTOCOL}. "
        f"Bump PROTOCOL_VERSION in grits_lab/versions.py to {PROTOCOL_VERSION + 1}, add scoop-v{PROTOCOL_VERSION + 1} "
        f"to docs/protocol.md, and regenerate: {COMMAND}")
