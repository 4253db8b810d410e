"""The registered Gymnasium env: the contract (check_env), declared spaces, seeding and rendering."""

from __future__ import annotations

import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import grits_lab.sim  # noqa: F401  (registers the Gymnasium env, grits_lab.sim.ENV_ID)
from grits_lab.errors import InputError
from grits_lab.sim import ENV_ID, ScoopEnv, ScoopGymEnv, nominal_expert_trajectory
from grits_lab.sim.foods import level_count, load_foods
from grits_lab.sim.gym_env import RELATIVE_SCALE, WORKSPACE
from grits_lab.sim.sim_config import SimConfig


def smallest_food_level() -> tuple[str, str]:
    """The (food, level) with the fewest particles in the library: the cheapest world to build."""
    library = load_foods()
    return min((level_count(library.get(name), name, level), name, level) for name in library.names() for level in library.get(name).levels)[1:]


FOOD, LEVEL = smallest_food_level()


def make(**kwargs):
    return gymnasium.make(ENV_ID, food=FOOD, level=LEVEL, **kwargs)


def make_absolute(**kwargs):
    """The env taking 9-D poses, as the expert trajectories are written."""
    return make(action_mode="absolute", **kwargs)


def test_the_registered_env_passes_gymnasiums_checker_without_warnings():
    env = make(render_mode="rgb_array")
    try:
        assert isinstance(env.unwrapped, gymnasium.Env) and isinstance(env.unwrapped, ScoopGymEnv)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)
        assert [str(w.message) for w in caught if "gymnasium" in w.filename] == []
    finally:
        env.close()


def test_observations_lie_in_the_declared_spaces_along_an_expert_scoop():
    env = make_absolute()
    try:
        obs, info = env.reset(seed=4)
        assert obs in env.observation_space
        traj = nominal_expert_trajectory(env.unwrapped.scene())[:20].astype(np.float32)
        assert all(a in env.action_space for a in traj)
        for action in traj:
            obs, reward, terminated, truncated, info = env.step(action)
            assert obs in env.observation_space
            assert reward <= 0 and not terminated
        assert info["step"] == 20
    finally:
        env.close()


def test_the_same_seed_gives_identical_observations_and_rewards():
    runs = []
    for _ in range(2):
        env = make_absolute()
        try:
            obs, _ = env.reset(seed=7)
            traj = nominal_expert_trajectory(env.unwrapped.scene())[:15]
            seen = [obs["ee_pose"].copy()]
            rewards = []
            for action in traj:
                obs, reward, *_ = env.step(action)
                seen.append(np.concatenate([obs["ee_pose"], obs["joint_pos"]]))
                rewards.append(reward)
            runs.append((seen, rewards, env.unwrapped.particle_positions()))
        finally:
            env.close()
    (obs_a, rew_a, pos_a), (obs_b, rew_b, pos_b) = runs
    assert all(np.array_equal(a, b) for a, b in zip(obs_a, obs_b)) and rew_a == rew_b
    assert np.array_equal(pos_a, pos_b)


def test_a_seeded_reset_builds_the_world_the_plain_env_builds_for_that_seed():
    gym_env = make().unwrapped
    plain = ScoopEnv()
    try:
        gym_env.reset(seed=12)
        plain.reset(seed=12, options={"food": FOOD, "level": LEVEL})
        assert np.array_equal(gym_env.particle_positions(), plain.particle_positions())
        assert np.array_equal(gym_env.target_bowl_pose(), plain.target_bowl_pose())
    finally:
        gym_env.close()
        plain.close()


@pytest.mark.parametrize("factory", [lambda: make().unwrapped, lambda: ScoopEnv()], ids=["gym", "plain"])
def test_reset_without_a_seed_continues_the_envs_own_generator(factory):
    sequences = []
    for _ in range(2):
        env = factory()
        try:
            options = None if isinstance(env, ScoopGymEnv) else {"food": FOOD, "level": LEVEL}
            env.reset(seed=3, options=options)
            seeds, targets = [], []
            for _ in range(2):
                env.reset(options=options)
                seeds.append(env.seed)
                targets.append(env.target_bowl_pose())
            sequences.append((seeds, targets))
        finally:
            env.close()
    (seeds_a, targets_a), (seeds_b, targets_b) = sequences
    assert seeds_a == seeds_b and len(set(seeds_a) | {3}) == 3
    assert all(np.array_equal(a, b) for a, b in zip(targets_a, targets_b))


def test_rgb_array_rendering_shows_the_scene_and_no_render_mode_renders_nothing():
    env = make(render_mode="rgb_array")
    try:
        env.reset(seed=0)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.shape == (360, 480, 3)
        assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 50  # a scene, not a blank image
    finally:
        env.close()
    quiet = make()
    try:
        quiet.reset(seed=0)
        assert quiet.unwrapped.render() is None
    finally:
        quiet.close()


def test_the_env_id_is_versioned_with_the_env_and_an_older_id_names_it():
    from grits_lab.versions import ENV_VERSION

    assert ENV_ID == f"grits_lab/Scoop-v{ENV_VERSION}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        with pytest.raises(gymnasium.error.DeprecatedEnv, match=f"use `{ENV_ID}`"):
            gymnasium.make("grits_lab/Scoop-v0")


def test_an_unknown_food_fails_when_the_env_is_made():
    with pytest.raises(InputError, match="no_such_food"):
        gymnasium.make(ENV_ID, food="no_such_food")


@pytest.mark.parametrize("action_mode", ["relative", "absolute"])
def test_both_action_modes_pass_the_checker(action_mode):
    env = make(action_mode=action_mode)
    try:
        assert env.action_space.shape == ((6,) if action_mode == "relative" else (9,))
        check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()


def test_the_registration_declares_the_truncation_step():
    env = make()
    try:
        assert env.spec.max_episode_steps == SimConfig().max_episode_steps == 400
    finally:
        env.close()


def random_ik_failures(action_mode: str, n: int = 20) -> tuple[int, float]:
    """(IK failures, largest commanded joint step in rad) over `n` uniformly random actions."""
    env = make(action_mode=action_mode)
    try:
        env.reset(seed=0)
        env.action_space.seed(0)
        failures, largest = 0, 0.0
        for _ in range(n):
            *_, info = env.step(env.action_space.sample())
            failures += int(info["ik_failure"])
            largest = max(largest, info["joint_step"])
        return failures, largest
    finally:
        env.close()


def test_a_random_agent_in_relative_mode_stays_reachable():
    failures, largest = random_ik_failures("relative")
    assert failures <= 2  # at most 10 % of 20 random actions (0 measured)
    assert largest < 0.5  # no flip to another arm posture
    absolute_failures, _ = random_ik_failures("absolute")
    assert absolute_failures >= 10  # what the absolute 2 m box gives a random agent


def test_a_relative_action_moves_the_commanded_pose_by_its_scale_and_stays_in_the_workspace():
    env = make().unwrapped
    try:
        env.reset(seed=1)
        start = env.relative_target(np.zeros(6))
        moved = env.relative_target(np.array([1.0, -0.5, 0.0, 0.0, 0.0, 0.0]))
        assert moved[:3] - start[:3] == pytest.approx([RELATIVE_SCALE.translation_m, -0.5 * RELATIVE_SCALE.translation_m, 0.0])
        assert moved[3:] == pytest.approx(start[3:])
        for _ in range(60):  # one second straight up: stops at the workspace's ceiling
            obs, *_ = env.step(np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0], dtype=np.float32))
        assert env.relative_target(np.zeros(6))[2] == pytest.approx(WORKSPACE[1][2])
        assert abs(obs["ee_pose"][2] - WORKSPACE[1][2]) < 0.02
    finally:
        env.close()


def test_reset_and_step_infos_carry_the_scoop_and_spill_metrics():
    env = make()
    try:
        _, info = env.reset(seed=2)
        keys = {"spilled", "scooped", "in_spoon", "spoon_coverage", "scoop_success", "spillage"}
        assert keys <= set(info["metrics"]) and info["metrics"]["spilled"] == 0
        *_, info = env.step(np.zeros(6, dtype=np.float32))
        assert keys <= set(info["metrics"]) and info["metrics"]["n_particles"] == env.unwrapped.metrics()["n_particles"]
    finally:
        env.close()


def test_the_vector_env_example_steps_two_envs_without_an_ik_failure():
    import runpy
    from pathlib import Path

    example = runpy.run_path(str(Path(__file__).parents[2] / "examples" / "gym_vector_env.py"))
    result = example["run"](n_envs=2, steps=5, food=FOOD, level=LEVEL)
    assert result["spilled"].shape == result["scooped"].shape == (2,)
    assert list(result["ik_failures"]) == [0, 0]


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_relative_action_that_is_not_finite_is_refused_naming_the_six_numbers_sent(bad):
    env = make().unwrapped
    env.reset(seed=0)
    action = np.zeros(6, np.float32)
    action[2] = bad
    with pytest.raises(ValueError, match=r"a relative action is 6 finite numbers .*\(dx, dy, dz, rx, ry, rz\); entry 2 \(dz\) is "):
        env.step(action)
    env.close()
