"""Spillage trial trajectories: feasible shifts that keep what they can, the exit towards the transfer, seeds as data."""

import numpy as np
import pytest

from grits_lab.config import config_from_dict

from grits_lab.collection.spillage_trials import SpillageConfig, expert_mean_trajectory, make_trial_spec, source_bowl_region
from grits_lab.data.trajectories import append_exit, shift_trajectory
from grits_lab.errors import ConfigError
from grits_lab.geometry import rot6d_to_matrix
from grits_lab.runners.work import WorkerContext, execute_spec
from grits_lab.sim.shapes import BowlGeometry

BOWL = BowlGeometry()


def _base_and_center():
    config = SpillageConfig()
    return expert_mean_trajectory(config), source_bowl_region(config)["center"]


def test_a_shift_into_the_wall_is_clipped_there_and_keeps_its_sideways_part():
    base, center = _base_and_center()
    traj, scale = shift_trajectory(base, np.array([0.07, 0.05, 0.0]), center, BOWL.inner_radius_at, BOWL.depth, BOWL.floor_thickness)
    rel, base_rel = traj[:, :3] - center, base[:, :3] - center
    below = rel[:, 2] < BOWL.depth
    radial = np.linalg.norm(rel[:, :2], axis=1)
    base_excess = np.maximum(np.linalg.norm(base_rel[:, :2], axis=1) - (BOWL.inner_radius_at(base_rel[:, 2]) - 0.02), 0)
    assert np.all(radial[below] <= BOWL.inner_radius_at(rel[below, 2]) - 0.02 + base_excess[below] + 1e-9)
    assert 0.2 < scale < 1.0  # clipped, but not collapsed to the base as a whole-trajectory scale would be
    # in the scoop (below the rim) the spoon moved towards +y, along the wall
    assert np.mean(rel[below, 1] - base_rel[below, 1]) > 0.01


def test_an_upward_shift_is_applied_in_full():
    base, center = _base_and_center()
    traj, scale = shift_trajectory(base, np.array([0.0, 0.0, 0.05]), center, BOWL.inner_radius_at, BOWL.depth, BOWL.floor_thickness)
    assert scale == 1.0
    np.testing.assert_allclose(traj[10:, 2] - base[10:, 2], 0.05)


def test_exit_leaves_the_bowl_at_the_requested_speed_and_holds():
    base, center = _base_and_center()
    direction = np.array([-0.15, 0.38])
    out = append_exit(base, center, direction, distance=0.14, rise=0.02, speed=0.5, hold_steps=5, control_hz=10.0)
    np.testing.assert_array_equal(out[: len(base)], base)
    exit_ = out[len(base):]
    r = np.linalg.norm(exit_[:, :2] - center[:2], axis=1)
    assert abs(r[-1] - 0.14) < 1e-6 and r[-1] > BOWL.outer_radius
    np.testing.assert_allclose(exit_[-5:], np.repeat(exit_[-1:], 5, axis=0))  # holds still
    np.testing.assert_allclose(exit_[:, 3:], np.repeat(base[-1:, 3:], len(exit_), axis=0))  # orientation kept
    moved = exit_[-1, :2] - base[-1, :2]
    assert moved @ direction > 0.99 * np.linalg.norm(moved) * np.linalg.norm(direction)
    steps = np.linalg.norm(np.diff(out[len(base) - 1:, :3], axis=0), axis=1)
    assert steps.max() <= np.pi / 2 * 0.5 / 10.0 * 1.05  # eased: peak speed pi/2 times the average
    slow = append_exit(base, center, direction, 0.14, 0.02, 0.25, 5, 10.0)
    assert len(slow) > len(out)


def test_a_tilted_exit_rolls_the_spoon_outside_the_bowl_about_its_direction_of_travel_and_holds_the_roll():
    base, center = _base_and_center()
    direction = np.array([-0.15, 0.38])
    level = append_exit(base, center, direction, 0.14, 0.02, 0.5, 5, 10.0)
    tilted = append_exit(base, center, direction, 0.14, 0.02, 0.5, 5, 10.0, tilt=np.deg2rad(30.0), tilt_steps=6)
    assert len(tilted) == len(level) + 6
    np.testing.assert_allclose(tilted[: len(level) - 5], level[:-5], atol=1e-9)  # the same path out, level
    np.testing.assert_array_equal(tilted[len(level) - 5:, :3], np.repeat(level[-1:, :3], 11, axis=0))  # rolls in place
    start = rot6d_to_matrix(base[-1, 3:9])
    relative = rot6d_to_matrix(tilted[len(level) - 5:, 3:9]) @ start.T  # the roll added at each step
    angles = np.degrees(np.arccos(np.clip((np.trace(relative, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert np.all(np.diff(angles) >= -1e-6) and 0 < angles[0] < 30.0
    np.testing.assert_allclose(angles[-5:], 30.0, atol=1e-4)  # held tilted while falling food lands
    r = np.linalg.norm(tilted[len(level) - 5:, :2] - center[:2], axis=1)
    assert np.all(r > BOWL.outer_radius)  # what the roll sheds falls outside the bowl
    axis = relative[-1] @ np.array([0.0, 0.0, 1.0]) - np.array([0.0, 0.0, 1.0])
    travel = np.array([direction[0], direction[1], 0.0]) / np.linalg.norm(direction)
    assert abs(axis @ travel) < 1e-9  # a roll about the travel direction moves 'up' only across it


def test_exit_tilts_are_drawn_per_trial_within_range_with_either_sign():
    config = config_from_dict(SpillageConfig, {"exit": {"kind": "exit", "tilt_deg": [10.0, 40.0]}})
    bowl, base = source_bowl_region(config), expert_mean_trajectory(config)
    tilts = np.array([make_trial_spec(config, base, bowl, "cube", k).params["trial"].exit_tilt_deg for k in range(30)])
    assert np.all((np.abs(tilts) >= 10.0) & (np.abs(tilts) <= 40.0))
    assert (tilts > 0).any() and (tilts < 0).any()
    assert tilts[3] == make_trial_spec(config, base, bowl, "cube", 3).params["trial"].exit_tilt_deg


def _run_candidate(tilt_deg: float) -> dict:
    config = config_from_dict(SpillageConfig, {
        "particles": {"fill_height": [0.02, 0.02], "radius": [0.005, 0.005]}, "shift": {"x": 0.0, "y": 0.0, "z": 0.0},
        "exit": {"kind": "exit", "tilt_deg": [tilt_deg, tilt_deg], "speed": [0.4, 0.4]}, "raw_cloud": False, "cloud": {"n_points": 64},
    })
    spec = make_trial_spec(config, expert_mean_trajectory(config), source_bowl_region(config), "sphere", 0)
    ctx = WorkerContext()
    try:
        result = execute_spec(spec, ctx)
    finally:
        ctx.close()
    assert result.ok, result.traceback
    return result.payload["meta"]


def test_a_level_exit_keeps_the_food_and_a_tipped_exit_spills_it():
    level, tipped = _run_candidate(0.0), _run_candidate(45.0)
    assert level["ik_failures"] == 0 and tipped["ik_failures"] == 0  # the spoon really goes where the trial says
    # A heaped spoon may shed a few grains off its top on a level exit at 0.4 m/s (at most a tenth of
    # its load); rolled 45 degrees it sheds its load.
    assert level["scooped"] >= 5 and level["spilled"] <= level["scooped"] // 10
    assert tipped["spilled"] >= level["spilled"] + 5 and tipped["label"] == 1


def test_the_default_exit_is_reachable_at_the_extremes_of_shift_and_tilt():
    from grits_lab.sim.env import ScoopEnv

    config = SpillageConfig()
    bowl, base = source_bowl_region(config), expert_mean_trajectory(config)
    e = config.exit
    env = ScoopEnv(config.sim)
    try:
        for dz, tilt in [(-config.shift.z, e.tilt_deg[1]), (config.shift.z, -e.tilt_deg[1])]:
            shifted = base.copy()
            shifted[10:, 2] += dz
            traj = append_exit(shifted, bowl["center"], e.direction_xy(), e.distance, e.rise, e.speed[1], e.hold_steps, config.sim.control_hz,
                               tilt=np.deg2rad(tilt), tilt_steps=e.tilt_steps)
            env.reset(seed=0)
            failures = [t for t, a in enumerate(traj) if env.step(a)[4]["ik_failure"]]
            assert failures == [], (dz, tilt, failures)
    finally:
        env.close()


def test_trial_specs_are_data_of_their_seed_and_end_outside_the_bowl():
    config = config_from_dict(SpillageConfig, {"exit": {"kind": "exit"}})
    bowl = source_bowl_region(config)
    base = expert_mean_trajectory(config)
    a = make_trial_spec(config, base, bowl, "cone", 3)
    b = make_trial_spec(config, base, bowl, "cone", 3)
    c = make_trial_spec(config, base, bowl, "cone", 4)
    np.testing.assert_array_equal(a.trajectory, b.trajectory)
    assert a.params["trial"].exit_speed == b.params["trial"].exit_speed
    assert a.params["trial"].exit_speed != c.params["trial"].exit_speed
    speeds = [make_trial_spec(config, base, bowl, "cube", k).params["trial"].exit_speed for k in range(20)]
    assert min(speeds) >= config.exit.speed[0] and max(speeds) <= config.exit.speed[1]
    end = a.trajectory[-1, :2] - bowl["center"][:2]
    assert np.linalg.norm(end) > BOWL.outer_radius
    bad = {"exit": {"kind": "exit", "tilt_deg": [30.0, 10.0]}}
    with pytest.raises(ConfigError, match="exit.tilt_deg"):
        config_from_dict(SpillageConfig, bad)
    off = config_from_dict(SpillageConfig, {"exit": {"enabled": False}})
    assert len(make_trial_spec(off, base, bowl, "cone", 3).trajectory) == len(base)
