"""The registered Gymnasium env: the contract (check_env), declared spaces, seeding and rendering."""

from __future__ import annotations

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import grits_lab.sim  # noqa: F401  (registers grits_lab/Scoop-v0)
from grits_lab.errors import InputError
from grits_lab.sim import ENV_ID, ScoopEnv, ScoopGymEnv, nominal_expert_trajectory
from grits_lab.sim.foods import level_count, load_foods


def smallest_food_level() -> tuple[str, str]:
    """The (food, level) with the fewest particles in the library: the cheapest world to build."""
    library = load_foods()
    return min((level_count(library.get(name), name, level), name, level) for name in library.names() for level in library.get(name).levels)[1:]


FOOD, LEVEL = smallest_food_level()


def make(**kwargs):
    return gymnasium.make(ENV_ID, food=FOOD, level=LEVEL, **kwargs)


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
    env = make()
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
        env = make()
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


def test_an_unknown_food_fails_when_the_env_is_made():
    with pytest.raises(InputError, match="no_such_food"):
        gymnasium.make(ENV_ID, food="no_such_food")
