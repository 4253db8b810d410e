"""One whole-task evaluation episode: the method's scoop (receding horizon), then transfer and pour, measured from particles.

Stages and metrics (SPEC, "Metrics"):
1. Scoop: the controller plans a chunk from the observation history, `n_action_steps` of it are
   executed, and it plans again, until it returns None, holds still (after `min_steps`), or
   `max_steps` actions ran. The spoon then holds for `settle_steps` and the scoop is judged:
   `scooped` = particles lifted in the spoon above the source rim; `scoop_success` by the food's
   rule (one item, or a third of the spoon covered); `spillage` = any particle spilled during
   the stage; `spilled_before_scoop` (Fig. 6) = the first spill came at or before the step the
   scoop completed (the first step with a successful load lifted, else the end of the stage).
2. Transfer: the target bowl is located from the cameras (grits_lab/evaluation/transfer.py), a
   level, collision-free path is executed. 3. Pour: roll the spoon over the target and settle.
`task_success` = scoop success, food transferred (one item, or at least half of the scooped
particles for small-particle foods) and nothing spilled in any stage.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from grits_lab.evaluation.controllers import ObsHistory, is_still
from grits_lab.evaluation.episode_scene import EpisodeScene
from grits_lab.evaluation.transfer import Obstacle, choose_transfer, locate_bowl
from grits_lab.geometry import cubic_pose_path
from grits_lab.policies.control import ScoopHook
from grits_lab.records import CPU_KERNELS, LOAD_ACCOUNT
from grits_lab.sim.env import matrix_to_pose9
from grits_lab.versions import cpu_kernels

if TYPE_CHECKING:  # annotations only: no import cost, no cycle
    from grits_lab.evaluation.evaluation_config import EvaluationConfig, TransferSettings
    from grits_lab.perception.composite import CloudBuilder
    from grits_lab.policies.control import Controller, ScoopSettings
    from grits_lab.runners import EpisodeSpec, WorkerContext
    from grits_lab.sim.env import ScoopEnv


def run_scoop(env: ScoopEnv, controller: Controller, scene: EpisodeScene, history: ObsHistory, settings: ScoopSettings,
              record_chunks: bool = False, hook: ScoopHook | None = None) -> dict[str, Any]:
    """Stage 1; returns the scoop's measurements, guidance diagnostics and timings.

    With `record_chunks`, also "chunks": every executed chunk's composite cloud at its start
    (3, N, 3), its first action's index in the scoop and the spilled count before it, plus the
    scoop's executed actions (T, 9) (see `rollout_chunk_episode`).

    `hook` (grits_lab/policies/control.py `ScoopHook`; None: the base, which changes nothing) gives
    what the simulator executes for each planned action, the settling hold included; the history the
    controller reads keeps what it asked for.
    """
    cloud_steps = int(getattr(controller, "cloud_steps", 0))
    image_steps = int(getattr(controller, "image_steps", 0))
    n_exec = settings.n_action_steps or getattr(controller, "n_action_steps", None)
    # Learned policies never say "done": they hold their last pose, as the demonstrations end.
    stops_when_still = bool(getattr(controller, "stops_when_still", False))
    encoder = getattr(getattr(getattr(controller, "policy", None), "config", None), "obs_encoder", None)

    def observe() -> None:
        index = len(history) - 1
        if cloud_steps and index not in history.clouds:
            history.clouds[index] = scene.cloud()
        if image_steps and index not in history.rgbd:
            history.rgbd[index] = scene.rgbd(tuple(encoder.image_size), encoder.cameras)

    hook = hook or ScoopHook()
    controller.reset(scene)
    steps, plans, completion_step = 0, 0, -1
    plan_times: list[float] = []
    diagnostics: list[dict[str, Any]] = []
    stop_reason = "max_steps"
    last_action = history.ee_pose[-1]
    executed: list[np.ndarray] = []
    chunk_log: list[tuple[int, np.ndarray, int]] = []
    while steps < settings.max_steps:
        observe()
        if record_chunks:
            chunk_cloud = scene.cloud()  # what the predictor sees when the chunk starts
            spilled_before = int(env.tracker.history[-1]) if env.tracker.history else 0
        chunk = controller.plan(history, scene)
        if chunk is None:
            stop_reason = "controller_done"
            break
        plans += 1
        plan_times.append(chunk.plan_time_s)
        if chunk.diagnostics:
            diagnostics.append(chunk.diagnostics)
        # Compared with the last commanded pose, not the measured one: under a load the arm
        # settles slightly off its command (a holding chunk 3.3 mm from the command was 4.2 mm from
        # the measured pose in a replay), which is no motion the policy asks for.
        if stops_when_still and steps >= settings.min_steps and is_still(chunk, last_action, settings.still_tolerance):
            stop_reason = "policy_holds"
            break
        actions = chunk.actions[: n_exec or len(chunk.actions)]
        if record_chunks:
            chunk_log.append((steps, chunk_cloud, spilled_before))
        ended = False
        for i, action in enumerate(actions):
            sent = hook.executed(action, scene.seed, plans - 1)
            obs, _, terminated, truncated, _ = env.step(sent)
            last_action = action
            executed.append(np.asarray(sent, dtype=np.float32))  # what the spoon was sent to
            steps += 1
            scene.advance()
            history.append(obs, action)
            remaining = len(actions) - i - 1
            if 0 < remaining < max(cloud_steps, image_steps):  # the history slots the next plan reads
                observe()
            if completion_step < 0 and env.metrics()["scoop_success"]:
                completion_step = steps - 1
            if terminated or truncated or steps >= settings.max_steps:
                ended = True
                stop_reason = "env_ended" if (terminated or truncated) else "max_steps"
                break
        if ended:
            break
    for _ in range(settings.settle_steps):
        env.step(hook.executed(last_action, scene.seed, plans - 1))
        scene.advance()
    metrics = env.metrics()
    end_step = steps - 1 if completion_step < 0 else completion_step
    first_spill = int(metrics["first_spill_step"])
    return {
        "metrics": metrics,
        "scoop_steps": steps,
        "n_plans": plans,
        "stop_reason": stop_reason,
        "completion_step": completion_step,
        "spilled_before_scoop": bool(0 <= first_spill <= max(end_step, 0)),
        "plan_time_mean_s": float(np.mean(plan_times)) if plan_times else 0.0,
        "plan_time_max_s": float(np.max(plan_times)) if plan_times else 0.0,
        "diagnostics": diagnostics,
        **({"chunks": {"log": chunk_log, "actions": executed, "spilled_over_time": list(env.tracker.history)}} if record_chunks else {}),
    }


def rollout_chunk_episode(chunks: dict[str, Any], n_action_steps: int, meta: dict[str, Any]) -> dict[str, Any] | None:
    """A policy rollout's scoop as a spillage-dataset episode (docs/datasets.md, contract 4), or None.

    Arrays: trajectory (T, 9) executed actions; chunk_start (C,) int32; chunk_cloud (C, 3, N, 3)
    float16, the composite cloud when the chunk started; chunk_spilled (C,) bool, whether the
    spilled count rose while the chunk's `n_action_steps` actions ran; chunk_spilled_horizon (C,)
    bool, whether food spilled at the end of the task left at or after the chunk's first action
    (`chunks["spill_steps"]`, the step at which each particle spilled at the end left, recorded
    after the transfer and pour; else after the scoop). Only whole chunks are kept (the predictor
    judges `n_action_steps` actions); labels come from the simulation's particle states.
    """
    from grits_lab.data.chunk_labels import horizon_labels

    actions = np.asarray(chunks["actions"], dtype=np.float32).reshape(-1, 9)
    spilled = np.asarray(chunks["spilled_over_time"], dtype=np.int64)
    until_delivery = np.asarray(chunks.get("spilled_until_delivery", spilled), dtype=np.int64)
    spill_steps = np.asarray(chunks["spill_steps"], dtype=np.int32)
    starts, clouds, labels = [], [], []
    for start, cloud, before in chunks["log"]:
        if start + n_action_steps > len(actions):
            continue
        starts.append(start)
        clouds.append(np.asarray(cloud, dtype=np.float16))
        labels.append(bool(spilled[start + n_action_steps - 1] > before))
    if not starts:
        return None
    horizon = horizon_labels(spill_steps, np.asarray(starts)).tolist()
    arrays = {
        "trajectory": actions,
        "chunk_start": np.asarray(starts, dtype=np.int32),
        "chunk_cloud": np.stack(clouds),
        "chunk_spilled": np.asarray(labels, dtype=bool),
        "chunk_spilled_horizon": np.asarray(horizon, dtype=bool),
        "spilled_over_time": spilled[: len(actions)].astype(np.int32),
        "spilled_until_delivery": until_delivery.astype(np.int32),
        "spill_steps": spill_steps,
    }
    return {"arrays": arrays, "meta": {**meta, "label": int(any(labels)), "label_horizon": int(any(horizon)),
                                       "n_action_steps": int(n_action_steps), "steps": int(len(actions)), "n_chunks": len(starts),
                                       "n_chunks_spilled": int(sum(labels)), "n_chunks_spilled_horizon": int(sum(horizon))}}


def summarize_guidance(diagnostics: list[dict[str, Any]]) -> dict[str, Any]:
    """Per-episode means of the sampler's per-plan diagnostics (guided and post-hoc plans), and the
    per-plan lists (`plan_*` columns): P(spill) of the unguided sample from the same noise and of
    the executed sample, the mean gradient norm and the executed chunk's displacement (mm)."""
    guided = [d for d in diagnostics if d.get("guided_steps", 0) > 0]
    if not guided:
        return {"guided_steps": 0, "p_spill_before": math.nan, "p_spill_after": math.nan,
                "guidance_grad_norm": math.nan, "guidance_displacement": math.nan,
                "p_spill_unguided": math.nan, "p_spill_guided": math.nan, "guidance_displacement_mm": math.nan}
    out: dict[str, Any] = {
        "guided_steps": int(sum(d["guided_steps"] for d in guided)),
        "p_spill_before": float(np.mean([d["cost_first"] for d in guided])),
        "p_spill_after": float(np.mean([d["cost_last"] for d in guided])),
        "guidance_grad_norm": float(np.mean([d["grad_norm_mean"] for d in guided])),
        "guidance_displacement": float(np.mean([d["displacement_total"] for d in guided])),
    }
    compared = [d for d in guided if "p_spill_unguided" in d]
    if compared:
        out.update({
            "p_spill_unguided": float(np.mean([d["p_spill_unguided"] for d in compared])),
            "p_spill_guided": float(np.mean([d["p_spill_guided"] for d in compared])),
            "guidance_displacement_mm": float(np.mean([d.get("displacement_mm", math.nan) for d in compared])),
            "plan_p_spill_unguided": [float(d["p_spill_unguided"]) for d in compared],
            "plan_p_spill_guided": [float(d["p_spill_guided"]) for d in compared],
            "plan_grad_norm": [float(d["grad_norm_mean"]) for d in compared],
            "plan_displacement_mm": [float(d.get("displacement_mm", math.nan)) for d in compared],
        })
    else:
        out.update({"p_spill_unguided": math.nan, "p_spill_guided": math.nan, "guidance_displacement_mm": math.nan})
    return out


def run_transfer(env: ScoopEnv, scene: EpisodeScene, settings: TransferSettings) -> dict[str, Any]:
    """Stages 2 and 3: locate the target, lift, carry the spoon level, pour, settle; returns the measurements.

    Each action runs under its stage's name (`ScoopEnv.set_stage`: lift, carry, pour, after_pour),
    so every particle spilled is attributed to the stage that lost it. The stages start from the
    pose the arm is commanded to (`ScoopEnv.anchor_pose_target`) and run at
    `settings.solver_iterations` (`ScoopEnv.set_solver_iterations`, reached over the first action) and
    `settings.time_step` (`ScoopEnv.set_time_step`). Besides the metrics:
    "ik_failures" (actions of the transfer and pour whose pose the arm could not reach),
    "max_joint_step_rad" (the largest change of a commanded joint angle in one action, rad) and
    "max_joint_speed_ratio" (the largest over that joint's Panda velocity limit: above 1 no Panda
    could follow; the flips to another arm posture that throw a load measured 0.6-1.7 rad, 3-8x);
    "plan" (the option taken, transfer.py `TransferOption.describe`, or "held: ..." when no option
    passed and `settings.no_option` is "hold": the arm keeps the spoon where the scoop left it),
    "reachable" (whether the reach check passed; None unchecked), "checks" (options checked before moving), "spilled_by_stage"
    (spilled count at the end of each stage), "carry_peak_speed_mps" / "carry_peak_accel_mps2"
    (of the spoon's commanded path in the lift and carry, from its per-action differences; the
    spoon's measured peak is `ScoopEnv.metrics()["carry_peak_spoon_accel_mps2"]`).
    """
    target = locate_bowl(scene.object_points("target_bowl"))
    truth = np.asarray(env.target_bowl_pose(), dtype=np.float64)[:3, 3]
    world = env.world
    source = world.source_geometry
    obstacles = [
        Obstacle(world.source_bowl_position[:2], source.outer_radius, world.source_bowl_position[2] + source.depth),
        Obstacle(target.centre[:2], target.rim_radius + 0.01, target.rim_height),
    ]
    spoon = world.spoon_geometry
    reach = math.hypot(spoon.half_length, spoon.half_width)
    current = matrix_to_pose9(scene.spoon_pose())
    env.anchor_pose_target()  # the lift starts where the arm is commanded, not where an unreachable scoop pose lay
    env.set_time_step(settings.time_step)  # before the check: the stages after the scoop step at it
    max_step = settings.max_speed / env.config.control_hz
    # The robot's base stands at the world origin (grits_lab/sim/world.py): radial = away from it.
    heading = math.atan2(target.centre[1], target.centre[0]) if settings.heading == "radial" else None
    def check(actions: np.ndarray) -> Any:
        # The very IK the motion will solve: along the spline through the actions and the holds after
        # them, which shape its last span (their findings count against the last action).
        holds = settings.settle_steps if settings.interpolation == "cubic" else 0
        whole = np.concatenate([actions, np.repeat(actions[-1:], holds, axis=0)])
        return env.check_path(whole, rest_pull=settings.rest_pull, touches=settings.avoid_arm_contact, ik_refine=settings.ik_refine,
                              stop_at_unreachable=settings.no_option == "hold", interpolation=settings.interpolation).folded(len(actions))

    heading_free = env.heading_free_path if settings.reach_check and settings.heading_free_lift else None
    plan = choose_transfer(current, target, obstacles, settings, max_step, reach, heading, check if settings.reach_check else None,
                           spoon.pour_edge(settings.pour_axis), heading_free)
    ik_failures, joint_steps, speed_ratios = 0, [0.0], [0.0]
    spilled_by_stage: dict[str, int] = {}

    def step(action: np.ndarray, stage: str, via: np.ndarray | None = None) -> None:
        nonlocal ik_failures
        if env.tracker.stage != stage:
            spilled_by_stage[env.tracker.stage] = int(env.metrics()["spilled"])
            env.set_stage(stage, rest_pull=settings.rest_pull, ik_refine=settings.ik_refine)
        info = (env.step(action) if via is None else env.step_along(via))[4]
        ik_failures += int(info["ik_failure"])
        joint_steps.append(float(info["joint_step"]))
        speed_ratios.append(float(info["joint_speed_ratio"]))
        scene.advance()

    held = bool(plan.n_checks) and not plan.reachable and settings.no_option == "hold"
    env.set_solver_iterations(settings.solver_iterations, ramp_steps=env.substeps)  # over the first action
    if held:  # no motion the arm can follow: it keeps the spoon where the scoop left it
        for _ in range(settings.settle_steps):
            step(current, "lift")
    else:
        actions = np.concatenate([plan.actions, np.repeat(plan.actions[-1:], settings.settle_steps, axis=0)])
        stages = list(plan.stages) + ["after_pour"] * settings.settle_steps
        via = (cubic_pose_path(matrix_to_pose9(env.pose_target), actions, env.config.substeps)
               if settings.interpolation == "cubic" else [None] * len(actions))
        for action, stage, poses in zip(actions, stages, via):
            step(action, stage, poses)
    metrics = env.metrics()
    spilled_by_stage[env.tracker.stage] = int(metrics["spilled"])
    moving = np.array([current] if held else [a for a, stage in zip(plan.actions, plan.stages) if stage != "pour"], dtype=np.float64)
    velocity = np.diff(np.concatenate([current[None, :3], moving[:, :3]]), axis=0) * env.config.control_hz
    accel = np.diff(np.concatenate([np.zeros((1, 3)), velocity, np.zeros((1, 3))]), axis=0) * env.config.control_hz
    return {
        "ik_failures": ik_failures,
        "max_joint_step_rad": max(joint_steps),
        "max_joint_speed_ratio": max(speed_ratios),
        "metrics": metrics,
        "spilled_by_stage": spilled_by_stage,
        "target_locate_error_m": float(np.linalg.norm(target.centre[:2] - truth[:2])),
        "target_fit_residual_m": target.residual,
        "transfer_steps": int((0 if held else len(plan.actions)) + settings.settle_steps),
        "pour_steps": 0 if held else plan.n_pour,
        "plan": f"held: no option passed ({plan.n_checks} checked)" if held else plan.option.describe(),
        "reachable": plan.reachable if plan.n_checks else None,
        "checks": plan.n_checks,
        "carry_peak_speed_mps": float(np.linalg.norm(velocity, axis=1).max()) if len(velocity) else 0.0,
        "carry_peak_accel_mps2": float(np.linalg.norm(accel, axis=1).max()) if len(accel) else 0.0,
    }


def begin_episode(env: ScoopEnv, builder: CloudBuilder, *, seed: int, food: str, level: str) -> tuple[EpisodeScene, ObsHistory]:
    """Reset the env for (food, level, seed); the scene's sensors and the history holding the first observation."""
    obs, _ = env.reset(seed=int(seed), options={"food": food, "level": level})
    history = ObsHistory()
    history.append(obs)
    return EpisodeScene(env, builder, seed), history


def run_task_episode(env: ScoopEnv, controller: Controller, config: EvaluationConfig, *, seed: int, food: str, level: str,
                     builder: CloudBuilder, hook: ScoopHook | None = None) -> dict[str, Any]:
    """The whole task for one (method, food, level, seed); returns the metric part of the record.
    `hook` perturbs the scoop from outside (`run_scoop`); its `record_columns` go into the record.

    With `config.rollout_chunks`, the record also holds "_chunks": the scoop as a spillage-dataset
    episode (`rollout_chunk_episode`), which the driver writes and drops from the record.
    """
    start = time.perf_counter()
    scene, history = begin_episode(env, builder, seed=seed, food=food, level=level)
    n_particles = int(env.metrics()["n_particles"])
    record_chunks = bool(getattr(config, "rollout_chunks", False))
    hook = hook or ScoopHook()
    scoop = run_scoop(env, controller, scene, history, config.scoop, record_chunks=record_chunks, hook=hook)
    m = scoop["metrics"]
    load = env.particle_counts().lifted.copy()  # the particles `scooped` counts, followed to the episode's end
    scoop_time = time.perf_counter() - start
    record: dict[str, Any] = {
        "n_particles": n_particles,
        "spilled": int(m["spilled"]),
        "scooped": int(m["scooped"]),
        "scoop_success": bool(m["scoop_success"]),
        "scoop_failure": not bool(m["scoop_success"]),
        "spillage": int(m["spilled"]) > 0,
        "spilled_before_scoop": scoop["spilled_before_scoop"],
        "spoon_coverage": float(m["spoon_coverage"]),
        "first_spill_step": int(m["first_spill_step"]),
        "completion_step": scoop["completion_step"],
        "scoop_steps": scoop["scoop_steps"],
        "scoop_stop_reason": scoop["stop_reason"],
        "ik_failures": int(m["ik_failures"]),
        "scoop_max_joint_speed_ratio": float(m["max_joint_speed_ratio"]),
        "scoop_slowed_actions": int(m["slowed_actions"]),
        "scoop_action_time_s": float(m["action_time_s"]),
        "scoop_arm_contact_steps": int(m["arm_contact_steps"]),
        "above_spoon_rim": int(m["above_spoon_rim"]),
        "scoop_sunk_below_table": int(m["sunk_below_table"]),
        "n_plans": scoop["n_plans"],
        "plan_time_mean_s": scoop["plan_time_mean_s"],
        "plan_time_max_s": scoop["plan_time_max_s"],
        "scoop_time_s": scoop_time,
        **hook.record_columns(),
        CPU_KERNELS: cpu_kernels(),
        **summarize_guidance(scoop["diagnostics"]),
    }
    transferred, spilled_total, transfer_time, final = 0, int(m["spilled"]), 0.0, m
    record.update({"target_locate_error_m": math.nan, "target_fit_residual_m": math.nan, "spilled_transfer": 0,
                   "transfer_ik_failures": 0, "transfer_max_joint_step_rad": math.nan, "transfer_max_joint_speed_ratio": math.nan,
                   "transfer_plan": "", "transfer_reachable": None, "transfer_checks": 0, "pour_steps": 0,
                   "carry_peak_speed_mps": math.nan, "carry_peak_accel_mps2": math.nan, "carry_peak_spoon_accel_mps2": math.nan, "transfer_arm_contact_steps": 0,
                   "transfer_slowed_actions": 0})
    if config.transfer.enabled and m["scooped"] > 0:
        t0 = time.perf_counter()
        tr = run_transfer(env, scene, config.transfer)
        final = tr["metrics"]
        transfer_time = time.perf_counter() - t0
        transferred = int(tr["metrics"]["transferred"])
        spilled_total = int(tr["metrics"]["spilled"])
        record.update({"target_locate_error_m": tr["target_locate_error_m"], "target_fit_residual_m": tr["target_fit_residual_m"],
                       "spilled_transfer": max(0, spilled_total - int(m["spilled"])),
                       "transfer_ik_failures": tr["ik_failures"], "transfer_max_joint_step_rad": tr["max_joint_step_rad"],
                       "transfer_max_joint_speed_ratio": tr["max_joint_speed_ratio"], "pour_steps": tr["pour_steps"],
                       "transfer_plan": tr["plan"], "transfer_reachable": tr["reachable"], "transfer_checks": tr["checks"],
                       "carry_peak_speed_mps": tr["carry_peak_speed_mps"], "carry_peak_accel_mps2": tr["carry_peak_accel_mps2"],
                       "carry_peak_spoon_accel_mps2": float(final["carry_peak_spoon_accel_mps2"]),
                       "transfer_arm_contact_steps": int(final["arm_contact_steps"]) - int(m["arm_contact_steps"]),
                       "transfer_slowed_actions": int(final["slowed_actions"]) - int(m["slowed_actions"])})
    needed = 1 if env.food.success_rule == "items" else max(1, math.ceil(0.5 * int(m["scooped"])))
    record.update({
        "transferred": transferred,
        "spilled_total": spilled_total,
        "transfer_time_s": transfer_time,
        "renders": scene.renders,
        "task_success": bool(m["scoop_success"]) and transferred >= needed and spilled_total == 0,
    })
    record["delivered_fraction"] = transferred / int(m["scooped"]) if int(m["scooped"]) else math.nan
    record["sunk_below_table"] = int(final["sunk_below_table"])  # at the episode's end (ScoopEnv.metrics)
    record.update(load_account(load, env.particle_counts(), env.tracker.spilled_flags))
    record.update(final["spill_attribution"])
    if record_chunks:
        n_exec = config.scoop.n_action_steps or getattr(controller, "n_action_steps", None) or 12
        scoop["chunks"]["spilled_until_delivery"] = list(env.tracker.history)  # through the transfer and pour
        scoop["chunks"]["spill_steps"] = env.spill_steps()
        record["_chunks"] = rollout_chunk_episode(scoop["chunks"], int(n_exec), {
            "food": food, "level": level, "seed": int(seed), "shape": food, "spilled": int(m["spilled"]),
            "scooped": int(m["scooped"]), "scoop_success": bool(m["scoop_success"])})
    return record


def load_account(load: np.ndarray, counts: Any, spilled: np.ndarray) -> dict[str, int]:
    """Where the particles of the lifted load (`load`, (N,) bool: lifted when the scoop ended) are at the
    episode's end, each counted once, in this order: in the target bowl and out of the spoon
    ("lifted_delivered"), still in the spoon ("lifted_in_spoon"), back in the source bowl
    ("lifted_in_source": fell off the spoon over it, or never left it), counted spilled
    ("lifted_spilled", `spilled` (N,) the tracker's flags), anywhere else ("lifted_elsewhere": resting
    on a rim, say). The five sum to `scooped`. counts: the end's `ParticleCounts`."""
    load = np.asarray(load, dtype=bool)
    delivered = load & counts.in_target & ~counts.in_spoon
    in_spoon = load & counts.in_spoon
    # in the source bowl's cylinder and inside its wall: under the flared rim, on the table, is outside
    in_source = load & counts.in_source & ~counts.outside_source & ~counts.in_spoon & ~delivered
    lost = load & np.asarray(spilled, dtype=bool) & ~(delivered | in_spoon | in_source)
    elsewhere = load & ~(delivered | in_spoon | in_source | lost)
    return dict(zip(LOAD_ACCOUNT, (int(delivered.sum()), int(in_spoon.sum()), int(in_source.sum()), int(lost.sum()),
                                   int(elsewhere.sum()))))


def evaluation_episode(spec: EpisodeSpec, context: WorkerContext) -> dict[str, Any]:
    """Work function (grits_lab/runners): one evaluation episode in a worker; models cached per worker."""
    import torch

    from grits_lab.evaluation.methods import build_controller, guidance_columns, method_spec
    from grits_lab.perception.env_clouds import builder_for_env
    from grits_lab.sim.env import worker_env

    start = time.perf_counter()
    p = spec.params["evaluation"]
    config = p.config
    torch.set_num_threads(config.num_threads)
    env = worker_env(context, config.sim)
    from grits_lab.config import config_fingerprint

    builder = context.cached(("cloud-builder", config_fingerprint(config.cloud)), lambda: builder_for_env(config.cloud, env))
    hook = p.hook or ScoopHook()
    controller = build_controller(p.method, config, p.paths, context.cached, noise_keys=hook.noise_keys)
    record = run_task_episode(env, controller, config, seed=spec.seed, food=spec.food, level=spec.level, builder=builder, hook=hook)
    rho, s = guidance_columns(p.method, config)
    record.update({
        "run_id": p.run_id, "method": p.method, "food": spec.food, "split": p.split, "level": spec.level,
        "trial": p.trial, "seed": spec.seed, "rho": rho, "s": s, "error": "",
        "guidance_step": config.guidance.step if method_spec(p.method, config).sampler == "guided" else "",
        "wall_time_s": time.perf_counter() - start,
        **{f"checkpoint_{k}": d for k, d in p.digests.items()},
    })
    return record
