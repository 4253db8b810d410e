"""Transfer: the target bowl is found from the cameras (segmentation + depth), and paths avoid the bowls."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grits_lab.evaluation.episode_scene import EpisodeScene
from grits_lab.evaluation.transfer import Obstacle, fit_circle, locate_bowl, path_is_clear, plan_transfer
from grits_lab.perception.composite import CloudConfig
from grits_lab.perception.env_clouds import builder_for_env
from grits_lab.errors import InputError
from grits_lab.sim import ScoopEnv, SimConfig

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def env():
    env = ScoopEnv(SimConfig())
    yield env
    env.close()


def test_circle_fit_recovers_an_arc():
    angles = np.linspace(0.2, 2.0, 50)
    xy = np.stack([0.3 + 0.06 * np.cos(angles), -0.1 + 0.06 * np.sin(angles)], 1)
    centre, radius, residual = fit_circle(xy)
    np.testing.assert_allclose(centre, [0.3, -0.1], atol=1e-9)
    assert abs(radius - 0.06) < 1e-9 and residual < 1e-9


@pytest.mark.parametrize("target_xy", [(0.38, 0.15), (0.62, 0.36), (0.5, 0.25)])
def test_target_bowl_located_within_a_few_cm(env, target_xy):
    env.reset(seed=1, options={"food": "chocolate_balls", "level": "low", "target_xy": target_xy})
    scene = EpisodeScene(env, builder_for_env(CloudConfig(n_points=32, cad_surface_samples=400), env), seed=1)
    estimate = locate_bowl(scene.object_points("target_bowl"))
    error = np.linalg.norm(estimate.centre[:2] - np.asarray(target_xy))
    assert error < 0.02, error
    assert abs(estimate.rim_height - env.world.target_geometry.depth) < 0.01


def test_transfer_path_goes_over_the_bowls_and_ends_above_the_target(env):
    env.reset(seed=2, options={"food": "chocolate_balls", "level": "low", "target_xy": (0.45, 0.3)})
    scene = EpisodeScene(env, builder_for_env(CloudConfig(n_points=32, cad_surface_samples=400), env), seed=2)
    target = locate_bowl(scene.object_points("target_bowl"))
    source = env.world.source_geometry
    src = env.world.source_bowl_position
    obstacles = [Obstacle(src[:2], source.outer_radius, src[2] + source.depth), Obstacle(target.centre[:2], target.rim_radius, target.rim_height)]
    start = np.concatenate([src + [0, 0, 0.08], [1, 0, 0, 0, 1, 0]]).astype(np.float32)
    path = plan_transfer(start, target, obstacles, clearance=0.04, pour_height=0.05, max_step=0.012, spoon_reach=0.036)
    assert np.linalg.norm(path[-1, :2] - target.centre[:2]) < 1e-6
    above = int(np.argmax(path[:, 2] >= path[:, 2].max() - 1e-9))  # first waypoint at the safe height
    assert path_is_clear(path, obstacles[:1], 0.036, start_index=above)
    assert np.all(np.linalg.norm(np.diff(path[:, :3], axis=0), axis=1) <= 0.012 + 1e-6)
    np.testing.assert_allclose(path[:, 3:], np.tile([1, 0, 0, 0, 1, 0], (len(path), 1)), atol=1e-6)  # level all the way
    low = start.copy()
    low[2] = src[2] + 0.02  # a straight line at this height would cut through the source bowl's wall
    assert not path_is_clear(np.stack([low, low + [0.2, 0, 0, 0, 0, 0, 0, 0, 0]]), obstacles[:1], 0.036)


def _angles_deg(path: np.ndarray) -> np.ndarray:
    from grits_lab.geometry import rot6d_to_matrix

    rots = [rot6d_to_matrix(p[3:9].astype(np.float64)) for p in path]
    return np.array([np.degrees(np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1))) for a, b in zip(rots, rots[1:])])


def test_a_tipped_spoon_is_levelled_gradually_and_arrives_pointing_away_from_the_robot():
    from grits_lab.evaluation.transfer import BowlEstimate, heading_rotation
    from grits_lab.geometry import matrix_to_rot6d, rot6d_to_matrix

    tipped = np.array([[0.96, 0, -0.28], [0, 1, 0], [0.28, 0, 0.96]])  # ~16 degrees tip-up, as scoops end
    tipped, _ = np.linalg.qr(tipped)
    tipped *= np.sign(np.diag(tipped))
    start = np.concatenate([[0.6, -0.1, 0.12], matrix_to_rot6d(tipped)]).astype(np.float32)
    target = BowlEstimate(np.array([0.35, 0.35, 0.0]), 0.06, 0.05, 100, 0.0)
    path = plan_transfer(start, target, [], clearance=0.04, pour_height=0.05, max_step=0.012, spoon_reach=0.036,
                         level_steps=8, target_heading=np.arctan2(0.35, 0.35))
    steps = _angles_deg(np.concatenate([start[None], path]))
    assert steps[:8].max() < 16 / 8 + 0.5  # the tilt goes in eighths, not in one jump
    final = rot6d_to_matrix(path[-1, 3:9].astype(np.float64))
    np.testing.assert_allclose(final, heading_rotation(np.pi / 4), atol=1e-6)
    np.testing.assert_allclose(final[:, 2], [0, 0, 1], atol=1e-6)  # level at the pour point
    one_jump = plan_transfer(start, target, [], 0.04, 0.05, 0.012, 0.036)
    assert _angles_deg(np.concatenate([start[None], one_jump]))[0] > 15


def _scene_obstacles(env, target_xy, seed=2):
    env.reset(seed=seed, options={"food": "chocolate_balls", "level": "low", "target_xy": target_xy})
    scene = EpisodeScene(env, builder_for_env(CloudConfig(n_points=32, cad_surface_samples=400), env), seed=seed)
    target = locate_bowl(scene.object_points("target_bowl"))
    src, source = env.world.source_bowl_position, env.world.source_geometry
    obstacles = [Obstacle(src[:2], source.outer_radius, src[2] + source.depth),
                 Obstacle(target.centre[:2], target.rim_radius + 0.01, target.rim_height)]
    return scene, target, obstacles


def _rolled(settings_class, **overrides):
    """Transfer settings with scoop-v5's roll pour (studies/post_scoop_losses/configs/transfer_pour_roll.yaml): by the robot's base
    PyBullet's solver alone stops short of its first option, which the reach-check tests need."""
    from grits_lab.config import load_yaml

    return settings_class(**{**load_yaml(REPO / "studies" / "post_scoop_losses" / "configs" / "transfer_pour_roll.yaml")["transfer"], **overrides})


def test_transfer_options_start_with_the_configured_one_and_never_repeat():
    from grits_lab.evaluation.evaluation_config import TransferSettings
    from grits_lab.evaluation.transfer import TransferOption, transfer_options

    settings = TransferSettings(level_steps=10, pour_height=0.01, alternative_pour_heights=[0.03, 0.05], pour_yaw_deg=90.0,
                                alternative_pour_yaw_deg=[-90.0])
    options = transfer_options(settings)
    assert options[0] == TransferOption(10, 0.0, 0.01, 0.0, 90.0)
    assert options[1] == TransferOption(10, 0.0, 0.01, 0.0, -90.0)  # the pour's heading varies fastest
    assert options[2] == TransferOption(10, 0.0, 0.01, 0.03, 90.0)  # the pour alternatives of a lift come before the next lift
    assert len(options) == len(set(options)) == 2 * 5 * 3 * 3 * 2  # level steps x headings x pour heights x offsets x pour headings
    assert transfer_options(TransferSettings(alternative_level_steps=[10], alternative_level_yaw_deg=[0.0], pour_height=0.01,
                                             alternative_pour_heights=[0.01], alternative_pour_offsets=[0.0],
                                             pour_yaw_deg=90.0, alternative_pour_yaw_deg=[90.0])) == options[:1]


def test_an_unreachable_pour_is_replaced_by_one_the_arm_reaches(env):
    """A target close to the robot's base with scoop-v9's IK (`ik_refine` off): PyBullet's solver
    stops short of the pour above its centre; the check finds it before moving and takes another
    option, which the arm follows within the Panda's joint velocity limits. (With the refinement
    the first option is reached: `test_the_ik_refinement_follows_a_path_pybullets_solver_stalls_on`.)"""
    import math

    from grits_lab.evaluation.evaluation_config import TransferSettings
    from grits_lab.evaluation.transfer import choose_transfer
    from grits_lab.sim.env import matrix_to_pose9

    scene, target, obstacles = _scene_obstacles(env, (0.30, 0.20))
    settings = _rolled(TransferSettings, alternative_pour_heights=[0.05])  # the pour the arm reaches here: 5 cm up, 3 cm out
    current = matrix_to_pose9(scene.spoon_pose())
    heading = math.atan2(target.centre[1], target.centre[0])
    check = lambda actions: env.check_path(actions, rest_pull=False, ik_refine=False)  # noqa: E731 (the stages after the scoop)
    unchecked = choose_transfer(current, target, obstacles, settings, 0.012, 0.036, heading, check=None)
    assert unchecked.option.pour_offset == 0.0 and unchecked.n_checks == 0
    assert check(unchecked.actions).unreachable[1:].any()
    plan = choose_transfer(current, target, obstacles, settings, 0.012, 0.036, heading, check=check)
    assert plan.reachable and plan.n_checks >= 2 and plan.option != unchecked.option
    env.set_stage("carry", ik_refine=False)
    infos = [env.step(a)[4] for a in plan.actions]
    assert not any(i["ik_failure"] for i in infos[1:])
    assert max(i["joint_speed_ratio"] for i in infos) <= 1.0
    centre = np.asarray(target.centre[:2])
    assert np.linalg.norm(plan.actions[-1, :2] - centre) < target.rim_radius  # still above the bowl
    assert plan.stages[0] == "lift" and plan.stages[-1] == "pour"
    assert plan.n_pour % settings.pour_steps == 0  # the roll, slowed as a whole where the arm needed it


def test_the_ik_refinement_follows_a_path_pybullets_solver_stalls_on(env):
    """The roll pour above a target by the robot's base: PyBullet's solver, seeded at the arm,
    stops short of its poses; refined by damped least squares from the arm (`ik_refine`, scoop-v10)
    every pose after the first is reached. Stopping at the first unreachable action reports the
    same first failure and fails every action after it."""
    import math

    from grits_lab.evaluation.evaluation_config import TransferSettings
    from grits_lab.evaluation.transfer import choose_transfer
    from grits_lab.sim.env import matrix_to_pose9

    scene, target, obstacles = _scene_obstacles(env, (0.30, 0.20))
    settings = _rolled(TransferSettings)
    heading = math.atan2(target.centre[1], target.centre[0])
    plan = choose_transfer(matrix_to_pose9(scene.spoon_pose()), target, obstacles, settings, 0.012, 0.036, heading, check=None)
    plain = env.check_path(plan.actions, rest_pull=False, ik_refine=False)
    refined = env.check_path(plan.actions, rest_pull=False, ik_refine=True)
    assert plain.unreachable[1:].any() and not refined.unreachable[1:].any()
    assert refined.speed_ratios.max() > 0
    stopped = env.check_path(plan.actions, rest_pull=False, ik_refine=False, stop_at_unreachable=True)
    first = 1 + int(np.argmax(plain.unreachable[1:]))
    assert np.array_equal(stopped.unreachable[:first + 1], plain.unreachable[:first + 1])
    assert stopped.unreachable[first:].all() and len(stopped.unreachable) == len(plan.actions)


def _fake_check(ratio_of):
    """A PathCheck stand-in: speed ratio of each action from `ratio_of(actions)`, nothing unreachable."""
    from types import SimpleNamespace

    def check(actions):
        ratios = np.asarray(ratio_of(actions), dtype=np.float64)
        return SimpleNamespace(unreachable=np.zeros(len(actions), bool), joint_steps=ratios * 0.2175, speed_ratios=ratios)
    return check


def test_a_motion_too_fast_for_the_panda_is_slowed_stage_by_stage_on_the_same_path():
    from grits_lab.evaluation.transfer import slow_to_limits

    start = np.array([0.0, 0, 0.1, 1, 0, 0, 0, 1, 0])
    actions = np.array([start + [0.01 * (i + 1), 0, 0, 0, 0, 0, 0, 0, 0] for i in range(6)])
    stages = ["lift"] * 2 + ["carry"] * 4
    # Joint speed proportional to the spoon's step: the carry's 1 cm steps ask for 2.5x the limit.
    ratio = _fake_check(lambda a: np.linalg.norm(np.diff(np.vstack([start[None], a])[:, :3], axis=0), axis=1) * 250)
    slowed, new_stages, answer, within = slow_to_limits(start, actions, stages, ratio, max_slowdown=8)
    assert within and answer.speed_ratios.max() <= 1.0
    # Both stages were too fast (2.5x): each action is cut in ceil(2.5 * 1.05) = 3, on the same straight path.
    assert new_stages == ["lift"] * 6 + ["carry"] * 12
    np.testing.assert_allclose(slowed[2::3], actions, atol=1e-6)
    np.testing.assert_allclose(np.diff(slowed[:, 0]), 0.01 / 3, atol=1e-6)


def test_a_posture_change_cannot_be_slowed_away_and_the_option_fails():
    from grits_lab.evaluation.transfer import slow_to_limits

    start = np.array([0.0, 0, 0.1, 1, 0, 0, 0, 1, 0])
    actions = np.array([start + [0.01 * (i + 1), 0, 0, 0, 0, 0, 0, 0, 0] for i in range(4)])
    # One jump of the IK's solution, the same size however finely the path is cut.
    jump = _fake_check(lambda a: np.where(np.arange(len(a)) == len(a) // 2, 1.8, 0.3))
    _, _, answer, within = slow_to_limits(start, actions, ["carry"] * 4, jump, max_slowdown=8)
    assert not within and answer.speed_ratios.max() > 1.0


def test_the_min_jerk_carry_starts_and_ends_at_rest_and_never_exceeds_the_peak_step():
    from grits_lab.evaluation.transfer import BowlEstimate, plan_transfer

    start = np.array([0.6, -0.1, 0.12, 1, 0, 0, 0, 1, 0], dtype=np.float32)
    target = BowlEstimate(np.array([0.45, 0.3, 0.0]), 0.058, 0.045, 100, 0.0)
    path = plan_transfer(start, target, [], clearance=0.04, pour_height=0.01, max_step=0.012, spoon_reach=0.036,
                         level_steps=10, profile="min_jerk")
    steps = np.linalg.norm(np.diff(np.vstack([start[None], path])[:, :3], axis=0), axis=1)
    assert steps.max() <= 0.012 + 1e-6
    across = np.flatnonzero(np.abs(np.diff(path[:, 1])) > 1e-9)  # the segment across, towards the target
    assert steps[across[0]] < 0.002 and steps[across[-1] + 1] < 0.002  # gentle start and stop
    assert abs(path[-1, 2] - (0.045 + 0.01)) < 1e-6


def test_a_non_positive_joint_step_limit_is_a_config_error():
    from grits_lab.errors import ConfigError
    from grits_lab.evaluation.evaluation_config import TransferSettings

    with pytest.raises(ConfigError, match="transfer.max_joint_step"):
        TransferSettings(max_joint_step=0.0)
    with pytest.raises(ConfigError, match="transfer.alternative_level_steps"):
        TransferSettings(alternative_level_steps=[0])


def test_without_a_passing_option_the_smallest_joint_step_is_taken():
    """Every option fails; the fallback prefers no flip over fewer unreachable poses."""
    from types import SimpleNamespace

    from grits_lab.evaluation.evaluation_config import TransferSettings
    from grits_lab.evaluation.transfer import BowlEstimate, choose_transfer

    settings = TransferSettings(alternative_level_steps=[], alternative_level_yaw_deg=[-60.0], alternative_pour_heights=[],
                                alternative_pour_offsets=[], alternative_pour_yaw_deg=[], slow_to_limits=False)
    start = np.array([0.6, -0.1, 0.12, 1, 0, 0, 0, 1, 0], dtype=np.float32)
    target = BowlEstimate(np.array([0.45, 0.3, 0.0]), 0.06, 0.05, 100, 0.0)
    answers = iter([(2, 1.4), (9, 0.35)])  # (unreachable actions, largest joint step) of each option

    def check(actions):
        n_bad, step = next(answers)
        unreachable = np.zeros(len(actions), dtype=bool)
        unreachable[-n_bad:] = True  # at the pour: a failure after the lift
        return SimpleNamespace(unreachable=unreachable, joint_steps=np.full(len(actions), step),
                               speed_ratios=np.full(len(actions), step / 0.2175), touches=None)

    plan = choose_transfer(start, target, [], settings, 0.012, 0.036, None, check)
    assert (plan.option.level_yaw_deg, plan.reachable, plan.n_checks) == (-60.0, False, 2)


def test_the_pour_puts_the_lip_the_food_leaves_by_over_the_targets_centre():
    from grits_lab.evaluation.transfer import BowlEstimate, heading_rotation, plan_transfer, pour_motion
    from grits_lab.geometry import rot6d_to_matrix

    start = np.array([0.6, -0.1, 0.12, 1, 0, 0, 0, 1, 0], dtype=np.float32)
    target = BowlEstimate(np.array([0.45, 0.3, 0.0]), 0.058, 0.045, 100, 0.0)
    heading = float(np.arctan2(0.3, 0.45))
    path = plan_transfer(start, target, [], 0.04, 0.005, 0.012, 0.036, target_heading=heading, profile="min_jerk", lip_offset=0.026)
    # The spoon's centre sits 2.6 cm along its own +y axis from the target's centre ...
    y_axis = heading_rotation(heading)[:, 1]
    np.testing.assert_allclose(path[-1, :2], target.centre[:2] + 0.026 * y_axis[:2], atol=1e-6)
    # ... and the roll lowers its -y lip, which then passes over the target's centre.
    pour = pour_motion(path[-1], 120.0, 30, "min_jerk")
    lip_local = np.array([0.0, -0.026, 0.01])
    lips = np.array([p[:3] + rot6d_to_matrix(p[3:9].astype(np.float64)) @ lip_local for p in pour])
    assert lips[-1, 2] < target.rim_height - 0.015  # well inside the bowl at the end of the roll
    assert np.linalg.norm(lips[len(lips) // 2, :2] - target.centre[:2]) < 0.01  # mid-roll, over the centre


def test_when_no_option_passes_the_arm_holds_the_spoon_instead_of_running_a_motion_it_cannot_follow(env):
    """A target beyond the arm's reach (1 m from its base; the Panda reaches 0.855 m) with no
    alternative to fall back on: the one option fails the check, and with `no_option: hold` the arm
    does not move (scoop-v3 ran it anyway and jumped)."""
    from grits_lab.evaluation.evaluation_config import TransferSettings
    from grits_lab.evaluation.task_episode import run_transfer

    scene, _, _ = _scene_obstacles(env, (0.85, 0.52))
    settings = _rolled(TransferSettings, alternative_level_steps=[], alternative_level_yaw_deg=[], alternative_pour_heights=[],
                       alternative_pour_offsets=[])
    before = env.spoon_pose()
    out = run_transfer(env, scene, settings)
    assert out["reachable"] is False and out["plan"].startswith("held: no option passed")
    assert out["transfer_steps"] == settings.settle_steps and out["pour_steps"] == 0 and out["ik_failures"] == 0
    assert np.linalg.norm(env.spoon_pose()[:3, 3] - before[:3, 3]) < 0.005
    assert out["max_joint_speed_ratio"] <= 1.0


@pytest.mark.parametrize("iterations", [100, None])
def test_the_stages_after_the_scoop_run_at_the_transfers_solver_iterations(env, iterations):
    from grits_lab.evaluation.evaluation_config import TransferSettings
    from grits_lab.evaluation.task_episode import run_transfer

    scene, _, _ = _scene_obstacles(env, (0.30, 0.20))
    assert env.world.client.getPhysicsEngineParameters()["numSolverIterations"] == env.config.solver_iterations  # the scoop's
    settings = _rolled(TransferSettings, alternative_level_steps=[], alternative_level_yaw_deg=[], alternative_pour_heights=[],
                       alternative_pour_offsets=[], solver_iterations=iterations)
    seen = []
    original, along = env.step, env.step_along

    def step(action):  # the setting every action of the transfer runs under, read as it starts
        seen.append(env.world.client.getPhysicsEngineParameters()["numSolverIterations"])
        return original(action)

    def step_along(poses):
        seen.append(env.world.client.getPhysicsEngineParameters()["numSolverIterations"])
        return along(poses)

    env.step, env.step_along = step, step_along
    try:
        run_transfer(env, scene, settings)
    finally:
        del env.step, env.step_along
    expected = env.config.solver_iterations if iterations is None else iterations
    # The first action ramps up from the scoop's (`set_solver_iterations(..., ramp_steps)`); every later one runs at it.
    assert seen[0] == env.config.solver_iterations and len(seen) > 1 and set(seen[1:]) == {expected}


@pytest.mark.parametrize("time_step", [1 / 240, None])
def test_the_stages_after_the_scoop_run_at_the_transfers_time_step(env, time_step):
    from grits_lab.evaluation.evaluation_config import TransferSettings
    from grits_lab.evaluation.task_episode import run_transfer

    scene, _, _ = _scene_obstacles(env, (0.30, 0.20))
    assert env.world.time_step == env.config.time_step  # the scoop's
    settings = _rolled(TransferSettings, alternative_level_steps=[], alternative_level_yaw_deg=[], alternative_pour_heights=[],
                       alternative_pour_offsets=[], time_step=time_step)
    seen, along = [], env.step_along

    def step_along(poses):  # the step every action of the transfer runs at, and its IK pieces
        seen.append((env.world.client.getPhysicsEngineParameters()["fixedTimeStep"], len(poses)))
        return along(poses)

    env.step_along = step_along
    try:
        out = run_transfer(env, scene, settings)
    finally:
        del env.step_along
    expected = env.config.time_step if time_step is None else time_step
    # The spline keeps its pieces (`sim.substeps` an action) at either step: the arm is asked for the same path.
    assert len(seen) == out["transfer_steps"] and {n for _, n in seen} == {env.config.substeps}
    assert [dt for dt, _ in seen] == pytest.approx([expected] * len(seen))


def test_transfer_time_step_outside_its_range_is_a_config_error():
    from grits_lab.errors import ConfigError
    from grits_lab.evaluation.evaluation_config import TransferSettings

    with pytest.raises(ConfigError, match="transfer.time_step"):
        TransferSettings(time_step=0.0)
    assert TransferSettings(time_step=None).time_step is None


def test_a_transfer_time_step_the_sim_cannot_step_at_is_refused_when_the_config_loads():
    """0.003 s is in range but leaves 33.3 steps per 0.1 s action: refused by the evaluation and
    the spillage configs at load, naming the key, before any episode runs."""
    from grits_lab.collection.spillage_trials import SpillageConfig
    from grits_lab.config import config_from_dict
    from grits_lab.errors import ConfigError
    from grits_lab.evaluation.evaluation_config import EvaluationConfig

    with pytest.raises(ConfigError, match=r"`transfer.time_step` must be .*whole number"):
        config_from_dict(EvaluationConfig, {"methods": ["expert"], "transfer": {"time_step": 0.003}})
    with pytest.raises(ConfigError, match=r"`exit.transfer.time_step` must be .*whole number"):
        config_from_dict(SpillageConfig, {"kind": "spillage", "output_dir": "unused", "exit": {"kind": "carry", "transfer": {"time_step": 0.003}}})
    # The lift-and-exit never runs the transfer: its settings' step is not the trial's.
    config_from_dict(SpillageConfig, {"kind": "spillage", "output_dir": "unused", "exit": {"kind": "exit", "transfer": {"time_step": 0.003}}})
    assert config_from_dict(EvaluationConfig, {"methods": ["expert"], "transfer": {"time_step": 1 / 240}}).transfer.time_step == 1 / 240


def test_transfer_solver_iterations_outside_their_range_are_a_config_error():
    from grits_lab.errors import ConfigError
    from grits_lab.evaluation.evaluation_config import TransferSettings

    with pytest.raises(ConfigError, match="transfer.solver_iterations"):
        TransferSettings(solver_iterations=0)


def test_a_lift_hold_keeps_the_lifted_spoon_still_over_the_source_bowl_before_the_carry():
    from grits_lab.evaluation.transfer import BowlEstimate, TransferOption, lift_length, option_motion
    from grits_lab.task.transfer_settings import TransferSettings

    start = np.array([0.6, -0.1, 0.06, 1, 0, 0, 0, 1, 0], dtype=np.float32)
    target = BowlEstimate(np.array([0.45, 0.3, 0.0]), 0.058, 0.045, 100, 0.0)
    option = TransferOption(10, 0.0, 0.005, 0.0)
    plain, plain_stages, _ = option_motion(start, target, [], TransferSettings(), 0.012, 0.036, None, option)
    held, held_stages, _ = option_motion(start, target, [], TransferSettings(lift_hold_steps=7), 0.012, 0.036, None, option)
    lift = lift_length(plain)
    assert len(held) == len(plain) + 7 and held_stages.count("lift") == plain_stages.count("lift") + 7
    np.testing.assert_array_equal(held[lift : lift + 7], np.repeat(plain[lift - 1 : lift], 7, axis=0))  # still, at the lift's top
    np.testing.assert_array_equal(held[lift + 7 :], plain[lift:])  # then the same carry and pour
    assert held_stages[lift + 7] == "carry"


def test_an_arm_that_would_touch_the_table_fails_the_option_only_when_asked():
    from types import SimpleNamespace

    from grits_lab.evaluation.transfer import BowlEstimate, choose_transfer
    from grits_lab.task.transfer_settings import TransferSettings

    start = np.array([0.6, -0.1, 0.06, 1, 0, 0, 0, 1, 0], dtype=np.float32)
    target = BowlEstimate(np.array([0.45, 0.3, 0.0]), 0.058, 0.045, 100, 0.0)

    def check(actions):  # within the limits and reachable, but the arm meets the table in the last 5 actions
        n = len(actions)
        return SimpleNamespace(unreachable=np.zeros(n, bool), joint_steps=np.full(n, 0.05), speed_ratios=np.full(n, 0.2),
                               touches=np.arange(n) >= n - 5)

    allowed = choose_transfer(start, target, [], TransferSettings(avoid_arm_contact=False), 0.012, 0.036, None, check)
    avoided = choose_transfer(start, target, [], TransferSettings(avoid_arm_contact=True, max_checks=3), 0.012, 0.036, None, check)
    assert allowed.reachable and allowed.n_checks == 1
    assert not avoided.reachable and avoided.n_checks == 3  # every option touches: none passes


def test_a_tip_pour_turns_the_spoon_about_its_tip_which_stays_over_the_targets_centre_while_the_hand_rises():
    from grits_lab.evaluation.transfer import BowlEstimate, heading_rotation, plan_transfer, pour_motion
    from grits_lab.geometry import rot6d_to_matrix
    from grits_lab.sim.shapes import SpoonGeometry

    start = np.array([0.6, -0.1, 0.12, 1, 0, 0, 0, 1, 0], dtype=np.float32)
    target = BowlEstimate(np.array([0.45, 0.3, 0.0]), 0.058, 0.045, 100, 0.0)
    heading = float(np.arctan2(0.3, 0.45)) + np.pi / 2
    path = plan_transfer(start, target, [], 0.04, 0.04, 0.012, 0.036, target_heading=heading, profile="min_jerk",
                         lip_offset=0.027, pour_axis="tip")
    x_axis = heading_rotation(heading)[:, 0]
    np.testing.assert_allclose(path[-1, :2], target.centre[:2] - 0.027 * x_axis[:2], atol=1e-6)  # tip over the centre
    pour = pour_motion(path[-1], 90.0, 30, "min_jerk", axis="tip", tip=0.027)
    rotations = [rot6d_to_matrix(p[3:9].astype(np.float64)) for p in pour]
    tips = np.array([p[:3] + r @ np.array([0.027, 0.0, 0.0]) for p, r in zip(pour, rotations)])
    np.testing.assert_allclose(tips, np.repeat(tips[:1], len(tips), axis=0), atol=1e-6)  # the tip stays put
    np.testing.assert_allclose(tips[0, :2], target.centre[:2], atol=1e-6)
    assert rotations[-1][2, 0] == pytest.approx(-1.0, abs=1e-6)  # the spoon's x axis points straight down at 90 degrees
    grasp = SpoonGeometry().grasp_point()
    hands = np.array([p[:3] + r @ grasp for p, r in zip(pour, rotations)])
    assert hands[:, 2].min() > tips[0, 2] + 0.05  # the hand stays above the tip (a roll swings it 6 cm below the spoon)


def test_the_pours_heading_alternatives_vary_fastest():
    from grits_lab.errors import ConfigError
    from grits_lab.evaluation.transfer import transfer_options
    from grits_lab.task.transfer_settings import TransferSettings

    settings = TransferSettings(pour_axis="tip", pour_yaw_deg=90.0, alternative_pour_yaw_deg=[-90.0],
                                alternative_pour_heights=[0.06], alternative_pour_offsets=[])
    first = [(o.pour_height, o.pour_yaw_deg) for o in transfer_options(settings)[:4]]
    assert first == [(0.04, 90.0), (0.04, -90.0), (0.06, 90.0), (0.06, -90.0)]
    assert transfer_options(TransferSettings(pour_yaw_deg=0.0))[0].describe().endswith("+0 cm out")  # no turn: as before
    assert transfer_options(settings)[1].describe().endswith("turned -90 deg")
    with pytest.raises(ConfigError, match="transfer.pour_axis"):
        TransferSettings(pour_axis="pitch")


def test_the_stages_after_the_scoop_refine_the_ik_and_the_scoop_does_not(env):
    """`set_stage` turns the refinement on after the scoop unless told otherwise; a reset starts
    without it, and `run_transfer` passes `transfer.ik_refine` to the check and to the motion."""
    from grits_lab.evaluation.evaluation_config import TransferSettings
    from grits_lab.evaluation.task_episode import run_transfer

    scene, _, _ = _scene_obstacles(env, (0.45, 0.28))
    assert env.ik_refine is False
    env.set_stage("lift")
    assert env.ik_refine is True
    env.set_stage("carry", ik_refine=False)
    assert env.ik_refine is False
    env.set_stage("scoop")
    assert env.ik_refine is False
    seen = {"check": set(), "solve": set()}
    check_path, solve = env.check_path, env.kinematics.solve

    def spy_check(*args, **kwargs):
        seen["check"].add(kwargs.get("ik_refine"))
        return check_path(*args, **kwargs)

    def spy_solve(*args, **kwargs):
        seen["solve"].add(kwargs.get("refine"))
        return solve(*args, **kwargs)

    env.check_path, env.kinematics.solve = spy_check, spy_solve
    try:
        run_transfer(env, scene, TransferSettings(ik_refine=False, max_checks=1))
    finally:
        env.check_path, env.kinematics.solve = check_path, solve
    assert seen["check"] == {False} and seen["solve"] == {False}


def test_a_check_told_to_stop_reports_every_action_after_its_first_failure_after_the_first(env):
    """The first action goes from where the scoop left the arm to the measured spoon pose: what it
    misses is the scoop's doing, so a check told to stop stops only after a failure from the second
    action on, and reports as many entries as actions (touches too)."""
    from grits_lab.sim.env import matrix_to_pose9

    env.reset(seed=2, options={"food": "chocolate_balls", "level": "low"})
    here = matrix_to_pose9(env.spoon_pose())
    away = here.copy()
    away[:3] = [1.6, 0.0, 0.4]  # twice the Panda's reach
    path = np.stack([away, here, here, here])  # the second action's way back starts out of reach too
    full = env.check_path(path, rest_pull=False, touches=True)
    assert full.unreachable.tolist() == [True, True, False, False]
    stopped = env.check_path(path, rest_pull=False, touches=True, stop_at_unreachable=True)
    assert stopped.unreachable.tolist() == [True, True, True, True]
    assert len(stopped.touches) == len(path) and stopped.speed_ratios[2:].tolist() == [0.0, 0.0]


def _turned(actions, yaw):
    """(T, 9) the poses turned by `yaw` rad about the vertical through each spoon centre."""
    from grits_lab.geometry import axis_angle_matrix, matrix_to_rot6d, rot6d_to_matrix

    turn = axis_angle_matrix([0.0, 0.0, 1.0], yaw)
    return np.array([np.concatenate([a[:3], matrix_to_rot6d(turn @ rot6d_to_matrix(a[3:9].astype(np.float64)))])
                     for a in actions], dtype=np.float32)


def test_heading_free_options_repeat_the_lifts_and_pours_without_heading_turns():
    from grits_lab.evaluation.transfer import transfer_options
    from grits_lab.task.transfer_settings import TransferSettings

    settings = TransferSettings()
    fixed, free = transfer_options(settings), transfer_options(settings, heading_free=True)
    assert not any(o.heading_free for o in fixed) and all(o.heading_free for o in free)
    assert {o.level_yaw_deg for o in free} == {0.0}
    assert [(o.level_steps, o.pour_height, o.pour_offset, o.pour_yaw_deg) for o in free] == \
        [(o.level_steps, o.pour_height, o.pour_offset, o.pour_yaw_deg) for o in fixed if o.level_yaw_deg == 0.0]
    assert "heading free" in free[0].describe()


def test_heading_free_lifts_are_tried_only_after_every_option_with_the_scoops_heading_failed():
    """A constructed arm that cannot lift with any fixed heading (every lift unreachable in its
    second action) but follows a lift it turns by 0.4 rad: the fixed options are checked first,
    `max_checks` at most, then the heading-free ones with a budget of their own; the first of them
    passes, its carry starting from the lift's turned heading. A heading-free lift the arm does not
    reach is never checked."""
    from types import SimpleNamespace

    from grits_lab.evaluation.transfer import BowlEstimate, choose_transfer, level_rotation, option_motion
    from grits_lab.task.transfer_settings import TransferSettings

    start = np.array([0.6, -0.1, 0.06, 1, 0, 0, 0, 1, 0], dtype=np.float32)
    target = BowlEstimate(np.array([0.45, 0.3, 0.0]), 0.058, 0.045, 100, 0.0)
    settings = TransferSettings(max_checks=5)
    checked = []

    def check(actions):
        n = len(actions)
        heading = level_rotation(actions[1])
        turned = abs(np.arctan2(heading[1, 0], heading[0, 0]) - 0.4) < 1e-4
        checked.append(turned)
        unreachable = np.zeros(n, bool)
        unreachable[1] = not turned
        return SimpleNamespace(unreachable=unreachable, joint_steps=np.full(n, 0.05), speed_ratios=np.full(n, 0.2), touches=None)

    free = lambda lift: (_turned(lift, 0.4), np.ones(len(lift), bool))  # noqa: E731
    plan = choose_transfer(start, target, [], settings, 0.012, 0.036, None, check, heading_free=free)
    assert plan.reachable and plan.option.heading_free and plan.option.level_steps == settings.level_steps
    # one check per fixed lift (its other pours skipped once it fails while rising), at most 5; then one
    assert checked == [False] * 5 + [True] and plan.n_checks == 6
    np.testing.assert_allclose(plan.actions[plan.stages.count("lift")][3:], plan.actions[plan.stages.count("lift") - 1][3:],
                               atol=1e-5)  # the carry starts level with the heading the lift ended with
    without = choose_transfer(start, target, [], settings, 0.012, 0.036, None, check)
    assert not without.reachable and without.n_checks == 5
    checked.clear()
    unreached = lambda lift: (_turned(lift, 0.4), np.arange(len(lift)) < 3)  # noqa: E731
    plan = choose_transfer(start, target, [], settings, 0.012, 0.036, None, check, heading_free=unreached)
    assert not plan.reachable and not plan.option.heading_free and checked == [False] * 5
    with pytest.raises(ValueError, match="heading-free"):
        option_motion(start, target, [], settings, 0.012, 0.036, None, plan.option.__class__(10, 0.0, 0.04, 0.0, 90.0, True))


def test_a_lift_the_scoop_left_unreachable_with_its_heading_is_followed_with_the_heading_free():
    """The oracle's fudge, low, trial 3 (experiments/oracle_transfer.yaml, root seed 9000): the scripted
    scoop leaves the wrist wound towards its limits, and under scoop-v10 no option passed the reach
    check, so the arm held the loaded spoon. With the heading free the lift unwinds the wrist and
    the spoon reaches the target bowl; the turned spoon is measured, not assumed: the episode's
    record says where its food went."""
    from dataclasses import replace

    from grits_lab.evaluation.evaluation_config import load_evaluation_config
    from grits_lab.evaluation.methods import build_controller
    from grits_lab.evaluation.task_episode import begin_episode, run_scoop, run_transfer
    from grits_lab.seeding import derive_seed

    config = load_evaluation_config(REPO / "experiments" / "oracle_transfer.yaml")
    env = ScoopEnv(config.sim)
    try:
        builder = builder_for_env(config.cloud, env)
        controller = build_controller("expert", config, {}, lambda key, factory: factory())
        outcomes = {}
        for free in (False, True):
            scene, history = begin_episode(env, builder, seed=derive_seed(config.seed, "fudge", "low", 3), food="fudge",
                                           level="low")
            scooped = int(run_scoop(env, controller, scene, history, config.scoop)["metrics"]["scooped"])
            outcomes[free] = run_transfer(env, scene, replace(config.transfer, heading_free_lift=free))
    finally:
        env.close()
    assert scooped > 0
    assert outcomes[False]["plan"].startswith("held") and outcomes[False]["metrics"]["transferred"] == 0
    released = outcomes[True]
    assert "heading free" in released["plan"] and released["reachable"]
    # The check solved the motion's own IK and slowed it to the Panda's limits: so did the motion.
    assert released["max_joint_speed_ratio"] <= 1.0 + 1e-6 and released["ik_failures"] == 0
    assert released["metrics"]["transferred"] >= 0.9 * scooped


def test_the_load_account_puts_every_lifted_particle_in_exactly_one_place():
    from grits_lab.evaluation.task_episode import load_account
    from grits_lab.records import LOAD_ACCOUNT
    from grits_lab.sim.spill_metrics import ParticleCounts

    # particles: delivered, in the spoon over the target, back in the source bowl, on the table,
    # on a rim, in the target but never lifted, one lifted and delivered that once was counted
    # spilled, and one on the table under the source's flared rim (inside its cylinder, outside its wall)
    f, t = False, True
    counts = ParticleCounts(in_spoon=np.array([f, t, f, f, f, f, f, f]), in_target=np.array([t, t, f, f, f, t, t, f]),
                            outside_source=np.array([t, t, f, t, t, t, t, t]), lifted=np.zeros(8, bool),
                            in_source=np.array([f, f, t, f, f, f, f, t]))
    load = np.array([t, t, t, t, t, f, t, t])
    spilled = np.array([f, f, f, t, f, f, t, t])
    account = load_account(load, counts, spilled)
    assert account == {"lifted_delivered": 2, "lifted_in_spoon": 1, "lifted_in_source": 1, "lifted_spilled": 2,
                       "lifted_elsewhere": 1}
    assert sum(account.values()) == load.sum() and tuple(account) == LOAD_ACCOUNT


def test_a_cubic_check_solves_the_very_ik_the_motion_along_the_spline_solves(env):
    """`check_path(..., interpolation="cubic")` on the kinematic copy ends at the joint target the arm
    is commanded to after moving along `cubic_pose_path` through the same actions with `step_along`,
    exactly; the straight-piece check is another motion's prediction."""
    import math

    from grits_lab.evaluation.transfer import choose_transfer
    from grits_lab.geometry import cubic_pose_path
    from grits_lab.sim.env import matrix_to_pose9
    from grits_lab.task.transfer_settings import TransferSettings

    scene, target, obstacles = _scene_obstacles(env, (0.45, 0.3))
    settings = TransferSettings()
    plan = choose_transfer(matrix_to_pose9(scene.spoon_pose()), target, obstacles, settings, 0.012, 0.036,
                           math.atan2(target.centre[1], target.centre[0]), check=None)
    actions = plan.actions[:40]  # the lift and the start of the carry
    env.anchor_pose_target()
    env.set_stage("lift", rest_pull=False, ik_refine=True)
    cubic = env.check_path(actions, interpolation="cubic")
    linear = env.check_path(actions)
    for poses in cubic_pose_path(matrix_to_pose9(env.pose_target), actions, env.config.substeps):
        env.step_along(poses)
    assert np.array_equal(cubic.joints, env._joint_target)
    assert not np.array_equal(linear.joints, env._joint_target)
    with pytest.raises(InputError, match="interpolation"):
        env.check_path(actions, interpolation="spline")


def test_a_folded_check_counts_what_the_holds_after_a_motion_found_against_its_last_action():
    from grits_lab.sim.env import PathCheck

    answer = PathCheck(np.array([False, False, False, True]), np.array([0.1, 0.2, 0.05, 0.3]), np.zeros(7),
                       np.array([0.4, 0.9, 0.2, 1.3]), np.array([False, False, False, False]))
    folded = answer.folded(2)
    assert folded.unreachable.tolist() == [False, True] and folded.speed_ratios.tolist() == [0.4, 1.3]
    assert folded.joint_steps.tolist() == [0.1, 0.3] and folded.touches.tolist() == [False, False]
    assert answer.folded(4) is answer
