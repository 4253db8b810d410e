"""Spillage trial trajectories: feasible shifts that keep what they can, the exit towards the transfer, seeds as data."""

import numpy as np

from grits_lab.config import config_from_dict

from grits_lab.data.spillage import SpillageConfig, _sim_config, expert_mean_trajectory, make_trial_spec, source_bowl_region
from grits_lab.data.trajectories import append_exit, shift_trajectory
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


def test_trial_specs_are_data_of_their_seed_and_end_outside_the_bowl():
    config = SpillageConfig()
    sim, bowl = _sim_config(config), source_bowl_region(config)
    base = expert_mean_trajectory(config)
    a = make_trial_spec(config, sim, base, bowl, "cone", 3)
    b = make_trial_spec(config, sim, base, bowl, "cone", 3)
    c = make_trial_spec(config, sim, base, bowl, "cone", 4)
    np.testing.assert_array_equal(a.trajectory, b.trajectory)
    assert a.params["trial"].exit_speed == b.params["trial"].exit_speed
    assert a.params["trial"].exit_speed != c.params["trial"].exit_speed
    speeds = [make_trial_spec(config, sim, base, bowl, "cube", k).params["trial"].exit_speed for k in range(20)]
    assert min(speeds) >= config.exit.speed[0] and max(speeds) <= config.exit.speed[1]
    end = a.trajectory[-1, :2] - bowl["center"][:2]
    assert np.linalg.norm(end) > BOWL.outer_radius
    off = config_from_dict(SpillageConfig, {"exit": {"enabled": False}})
    assert len(make_trial_spec(off, sim, base, bowl, "cone", 3).trajectory) == len(base)
