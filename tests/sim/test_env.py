"""The scooping world's behaviour: determinism, settling, scooping, spilling, cameras, IK failures."""

from __future__ import annotations

import numpy as np
import pytest

from grits_lab.errors import InputError
from grits_lab.sim import ScoopEnv, SimConfig, expert_trajectory, nominal_expert_trajectory, play_episode, play_trajectory
from grits_lab.sim.env import matrix_to_pose9
from grits_lab.sim.expert import spoon_orientation
from grits_lab.sim.foods import level_count, load_foods

ALL_FOODS = load_foods().names()


@pytest.fixture(scope="module")
def env():
    e = ScoopEnv()
    yield e
    e.close()


def hover_outside(env: ScoopEnv, steps: int) -> np.ndarray:
    """A trajectory that keeps the spoon above the table beside the source bowl, never entering it."""
    home = np.array(env.scene().spoon_home)
    goal = home.copy()
    goal[:3] = [0.45, -0.05, 0.12]
    return np.linspace(home, goal, steps)


def test_same_seed_gives_an_identical_episode(env):
    traj = None
    records, observations = [], []
    for _ in range(2):
        env.reset(seed=11, options={"food": "soybeans", "n_particles": 40})
        traj = nominal_expert_trajectory(env.scene())[:30] if traj is None else traj
        obs_seen = []
        record = play_trajectory(env, traj, on_step=lambda t, e, obs: obs_seen.append(obs["ee_pose"].copy()))
        records.append(record.to_dict())
        observations.append(np.array(obs_seen))
        positions = env.particle_positions()
        observations[-1] = (observations[-1], positions)
    for r in records:
        r.pop("wall_time_s")
    assert records[0] == records[1]
    assert np.array_equal(observations[0][0], observations[1][0])
    assert np.array_equal(observations[0][1], observations[1][1])


def test_a_different_seed_gives_a_different_world(env):
    env.reset(seed=1, options={"food": "soybeans", "n_particles": 30})
    a = env.particle_positions(), env.target_bowl_pose()
    env.reset(seed=2, options={"food": "soybeans", "n_particles": 30})
    b = env.particle_positions(), env.target_bowl_pose()
    assert not np.allclose(a[0], b[0]) and not np.allclose(a[1], b[1])


@pytest.mark.parametrize("food", ALL_FOODS)
def test_every_food_settles_without_spilling_while_the_spoon_waits(env, food):
    level = list(env.foods.get(food).levels)[-1]  # the largest quantity: the hardest to hold
    env.reset(seed=5, options={"food": food, "level": level})
    record = play_trajectory(env, hover_outside(env, 5))
    assert record.spilled == 0 and record.scooped == 0 and record.n_particles == level_count(env.foods.get(food), food, level)
    # Every particle rests inside the bowl, below its rim, on (not in) the floor; the pile is at
    # rest (isolated contact pops of a single particle aside) and nothing flies.
    pos = env.particle_positions() - env.source_bowl_pose()[:3, 3]
    geometry = env.world.source_geometry
    assert np.linalg.norm(pos[:, :2], axis=1).max() < geometry.rim_radius
    assert pos[:, 2].max() < geometry.depth
    resting = np.array([p.radius for p in env.world.particle_components])[env.world.particle_component_index]
    assert (pos[:, 2] - geometry.floor_thickness - resting).min() > -0.004  # sinks < 4 mm into the 6 mm floor
    speeds = env.world.particle_speeds()
    assert np.percentile(speeds, 95) < 0.02 and speeds.max() < 0.3


@pytest.fixture(scope="module")
def scooped(env):
    """soybeans, low: the randomized expert scoop; the env is left holding the loaded spoon."""
    record, traj = play_episode(env, "soybeans", "low", seed=0)
    return record, traj


def test_expert_scoops_without_spilling(scooped):
    record, traj = scooped
    assert record.scoop_success and not record.spillage and record.ik_failures == 0
    assert record.scooped >= 10 and record.spoon_coverage >= 1 / 3
    assert record.spilled_over_time == [0] * len(traj)


def test_particles_neither_pass_through_nor_jitter_out_of_a_held_spoon(env, scooped):
    before = env.metrics()["scooped"]
    held = matrix_to_pose9(env.spoon_pose())
    for _ in range(10):  # hold still for 1 s
        env.step(held)
    assert env.metrics()["scooped"] == before


def _tip_over_table(env, tip_actions):
    start = matrix_to_pose9(env.spoon_pose())
    over_table = start.copy()
    over_table[:3] = [0.45, -0.22, 0.16]
    tipped = over_table.copy()
    tipped[3:] = matrix_to_pose9(np.block([[spoon_orientation(0, 0) @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]), np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]]))[3:]
    return np.concatenate([np.linspace(start, over_table, 15), np.linspace(over_table, tipped, tip_actions), np.repeat(tipped[None], 10, 0)])


def test_tipping_the_loaded_spoon_over_the_table_spills(env, scooped):
    record, traj = scooped
    path = _tip_over_table(env, 25)
    ratios = env.check_path(path).speed_ratios
    rec = play_trajectory(env, path)
    assert rec.spillage and rec.spilled >= record.scooped // 2
    assert rec.first_spill_step > len(traj)  # nothing spilled during the scoop itself
    assert rec.spilled_over_time == sorted(rec.spilled_over_time)
    # Every grain left from the spoon (play_trajectory names no stage: all "scoop"). The wrist's
    # flip as the roll nears 90 deg asks for more than the Panda's limit; the arm slows it to the
    # limit (sim.joint_speed_cap), so nothing is thrown: every grain fell off the moving spoon.
    assert rec.spill_attribution["spilled_scoop_off_spoon"] == rec.spilled == sum(rec.spill_attribution.values())
    assert ratios.max() > 1.0 and env.metrics()["slowed_actions"] > 0


def test_food_thrown_by_a_tip_faster_than_a_panda_can_move_is_attributed_to_the_arm():
    # Only an arm allowed past the Panda's limits (joint_speed_cap null, scoop-v7 and earlier) throws.
    env = ScoopEnv(SimConfig(joint_speed_cap=None))
    try:
        play_episode(env, "soybeans", "low", seed=0)
        path = _tip_over_table(env, 3)
        assert env.check_path(path).speed_ratios.max() > 1.0
        rec = play_trajectory(env, path)
        assert rec.spilled > 0
        assert rec.spill_attribution["spilled_scoop_posture_flip"] >= rec.spilled - 1
        assert env.metrics()["slowed_actions"] == 0
    finally:
        env.close()


@pytest.mark.parametrize("food", ["mung_beans", "brown_rice", "sago"])
def test_a_full_bowl_holds_its_food_through_a_deep_drag(env, food):
    """Physics at full-bowl counts: a scoop dug 5 mm above the floor through the high level loses
    nothing through the bowl's floor or walls, and no grain ends inside the spoon's plate."""
    env.reset(seed=1, options={"food": food, "level": "high"})
    traj = nominal_expert_trajectory(env.scene(), env.config.control_hz)
    record = play_trajectory(env, traj)
    pos = env.particle_positions() - env.source_bowl_pose()[:3, 3]
    geometry = env.world.source_geometry
    r = np.linalg.norm(pos[:, :2], axis=1)
    in_bowl = r < float(geometry.rim_radius)
    # Nothing under the floor's top or outside the wall's outer face inside the bowl's height.
    assert pos[:, 2].min() > geometry.floor_thickness - 0.004
    wall_outer = geometry.inner_radius_at(pos[:, 2]) + geometry.wall_thickness
    assert not np.any((pos[:, 2] < geometry.depth) & (r > wall_outer) & (r < geometry.outer_radius + 0.02))
    assert in_bowl.sum() + record.scooped + record.spilled >= record.n_particles - 1
    assert record.scooped >= 10


def test_a_trajectory_that_never_enters_the_bowl_is_a_scoop_failure(env):
    env.reset(seed=3, options={"food": "mung_beans", "level": "low"})
    record = play_trajectory(env, hover_outside(env, 20))
    assert record.scoop_failure and not record.scoop_success and record.scooped == 0 and record.spilled == 0


@pytest.mark.parametrize("food", ["chocolate_balls", "dried_jujube", "orange"])
def test_expert_lifts_training_foods_without_spilling(env, food):
    level = list(env.foods.get(food).levels)[0]
    record, _ = play_episode(env, food, level, seed=1)
    assert record.scoop_success and not record.spillage, record.summary()


@pytest.mark.slow
def test_expert_succeeds_on_most_training_episodes(env):
    outcomes = []
    for food in env.foods.names("train"):
        for level in env.foods.get(food).levels:
            for seed in range(3):
                record, _ = play_episode(env, food, level, seed=seed)
                outcomes.append(record.scoop_success and not record.spillage)
    assert np.mean(outcomes) >= 0.7, np.mean(outcomes)


def test_expert_is_seeded_and_stays_near_the_nominal_scoop(env):
    env.reset(seed=0, options={"food": "orange"})
    scene = env.scene()
    a = expert_trajectory(scene, np.random.default_rng(4))
    b = expert_trajectory(scene, np.random.default_rng(4))
    c = expert_trajectory(scene, np.random.default_rng(5))
    nominal = nominal_expert_trajectory(scene)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a.shape[1] == 9 and abs(len(a) - len(nominal)) <= 12
    lowest = a[np.argmin(a[:, 2])]
    assert np.linalg.norm(lowest[:2] - np.array(scene.source_bowl_center[:2])) < scene.source_bowl_floor_radius


def test_cameras_see_the_particles_where_they_are(env):
    env.reset(seed=2, options={"food": "soybeans", "level": "low"})
    food_ids = set(env.segmentation_ids()["food"])
    positions = env.particle_positions()
    seen = 0
    for image in env.render_cameras().values():
        assert image.rgb.shape == (image.segmentation.shape + (3,)) and image.rgb.dtype == np.uint8
        mask = np.isin(image.segmentation, list(food_ids))
        assert mask.sum() > 50
        v, u = np.nonzero(mask)
        z = image.depth[v, u].astype(np.float64)
        k = image.intrinsics
        cam = np.stack([(u - k[0, 2]) * z / k[0, 0], (v - k[1, 2]) * z / k[1, 1], z, np.ones_like(z)])
        world = (image.camera_to_world @ cam)[:3].T
        nearest = np.min(np.linalg.norm(world[:, None, :] - positions[None, :, :], axis=2), axis=1)
        assert np.median(nearest) < 0.006  # surface points lie within a particle radius of a centre
        seen += 1
    assert seen == len(env.config.cameras)


def test_unreachable_poses_are_counted_not_fatal(env):
    env.reset(seed=0, options={"food": "orange"})
    far = np.array(env.scene().spoon_home)
    far[:3] = [1.6, 0.0, 0.3]
    _, _, _, _, info = env.step(far)
    assert info["ik_failure"] and info["ik_failures"] == 1
    assert env.metrics()["ik_failures"] == 1


def test_joint_step_is_the_largest_commanded_joint_change_of_the_action(env):
    obs, _ = env.reset(seed=0, options={"food": "orange"})
    hold = obs["ee_pose"].astype(np.float64)
    assert env.step(hold)[4]["joint_step"] < 0.01  # holding the measured pose asks (almost) nothing of the arm
    near = hold.copy()
    near[2] += 0.01  # 1 cm up in one 0.1 s action: well within the Panda's joint speeds
    step = env.step(near)[4]["joint_step"]
    assert 1e-4 < step < 0.22


def test_check_path_answers_what_step_then_does_without_touching_the_world(env):
    obs, _ = env.reset(seed=0, options={"food": "orange"})
    start = obs["ee_pose"].astype(np.float64)
    path = np.tile(start, (6, 1))
    path[:3, 2] += np.linspace(0.01, 0.03, 3)  # up 3 cm
    path[3:, :3] = [1.6, 0.0, 0.3]  # then out of the arm's reach
    spoon_before = env.world.spoon_matrix().copy()
    check = env.check_path(path)
    np.testing.assert_array_equal(env.world.spoon_matrix(), spoon_before)
    assert env.step_count == 0
    infos = [env.step(a)[4] for a in path]
    np.testing.assert_array_equal(check.unreachable, [i["ik_failure"] for i in infos])
    np.testing.assert_array_equal(check.joint_steps, [i["joint_step"] for i in infos])
    assert check.unreachable.tolist() == [False] * 3 + [True] * 3


def test_bad_actions_and_options_are_input_errors(env):
    env.reset(seed=0, options={"food": "orange"})
    with pytest.raises(InputError):
        env.step(np.zeros(7))
    with pytest.raises(InputError):
        env.step(np.full(9, np.nan))
    with pytest.raises(InputError, match="unknown food"):
        env.reset(seed=0, options={"food": "pizza"})
    with pytest.raises(InputError, match="level"):
        env.reset(seed=0, options={"food": "orange", "level": "huge"})


def test_a_particle_inside_the_table_is_counted_as_sunk(env):
    """No food rests with its centre below the table's top; a particle there passed through a bowl's
    floor or the table (a simulation fault), which `sunk_below_table` counts."""
    env.reset(seed=0, options={"food": "soybeans", "level": "low"})
    assert env.metrics()["sunk_below_table"] == 0  # settled food rests on the floor, above the table's top
    world = env.world
    body = int(world.particles[0])
    src = world.source_bowl_position
    world.client.resetBasePositionAndOrientation(body, [src[0], src[1], -0.006], [0, 0, 0, 1])
    assert env.metrics()["sunk_below_table"] == 1
