"""The Panda's kinematic copy: its Jacobian, the damped least-squares refinement and what `solve`
does with it."""

from __future__ import annotations

import numpy as np
import pytest

from grits_lab.geometry import axis_angle_matrix, rotation_vector
from grits_lab.sim.robot import FINE_IK, REST_POSE, PandaKinematics


@pytest.fixture(scope="module")
def kin():
    k = PandaKinematics()
    yield k
    k.close()


@pytest.mark.parametrize("angle", [0.0, 1e-7, 0.4, 2.5, np.pi - 1e-6])
def test_rotation_vector_inverts_axis_angle_matrix(angle):
    axis = np.array([0.3, -0.8, 0.5]) / np.linalg.norm([0.3, -0.8, 0.5])
    assert np.allclose(rotation_vector(axis_angle_matrix(axis, angle)), axis * angle, atol=1e-9)


def test_the_jacobian_is_the_derivative_of_forward_kinematics(kin):
    q = np.array(REST_POSE) + np.array([0.1, -0.2, 0.3, 0.2, -0.1, 0.1, 0.2])
    jac, h = kin.jacobian(q), 1e-3  # PyBullet's link states are single precision: central differences
    for j in range(7):
        dq = np.zeros(7)
        dq[j] = h
        ahead, behind = kin.forward(q + dq), kin.forward(q - dq)
        assert np.allclose((ahead[:3, 3] - behind[:3, 3]) / (2 * h), jac[:3, j], atol=2e-3)
        assert np.allclose(rotation_vector(ahead[:3, :3] @ behind[:3, :3].T) / (2 * h), jac[3:, j], atol=2e-3)


def test_refine_reaches_a_pose_near_the_seed_by_a_small_joint_motion(kin):
    q0 = np.array(REST_POSE)
    goal = np.array(REST_POSE) + np.array([0.05, -0.04, 0.03, 0.06, -0.05, 0.04, 0.03])
    target = kin.forward(goal)
    q = kin.refine(target, q0, FINE_IK)
    e = kin.residual(target, q)
    assert FINE_IK.reached(float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:])))
    # each step is least-norm: the path ends no farther from the seed than the joints that made the target
    assert np.linalg.norm(q - q0) <= 1.01 * np.linalg.norm(goal - q0)


def test_refine_keeps_every_joint_inside_its_limits_for_a_pose_out_of_reach(kin):
    target = kin.forward(np.array(REST_POSE))
    target[:3, 3] = [1.6, 0.0, 0.4]  # twice the Panda's reach
    q = kin.refine(target, np.array(REST_POSE), FINE_IK, iterations=60)
    assert np.all(q >= np.array(kin.lower[:7]) - 1e-12) and np.all(q <= np.array(kin.upper[:7]) + 1e-12)
    result = kin.solve(target, np.array(REST_POSE), 0.01, 0.15, rest_pull=False, converged=FINE_IK, refine=True)
    assert not result.ok


def test_solve_with_refine_is_never_farther_from_the_pose_than_without(kin):
    rng = np.random.default_rng(0)
    lower, upper = np.array(kin.lower[:7]), np.array(kin.upper[:7])
    for _ in range(5):
        seed = np.clip(np.array(REST_POSE) + rng.normal(0, 0.3, 7), lower, upper)
        target = kin.forward(np.clip(seed + rng.normal(0, 0.05, 7), lower, upper))
        plain = kin.solve(target, seed, 0.01, 0.15, rest_pull=False, converged=FINE_IK)
        refined = kin.solve(target, seed, 0.01, 0.15, rest_pull=False, converged=FINE_IK, refine=True)
        assert refined.miss <= plain.miss + 1e-12
        assert refined.ok


def test_rotation_between_turns_one_direction_onto_the_other():
    from grits_lab.geometry import rotation_between

    for a, b in [([0.3, 0.2, 0.9], [0.0, 0.0, 1.0]), ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]), ([0.0, 0.0, 1.0], [0.0, 0.0, -1.0])]:
        a, b = np.array(a) / np.linalg.norm(a), np.array(b)
        v = rotation_between(a, b)
        assert np.allclose(axis_angle_matrix(v / np.linalg.norm(v), np.linalg.norm(v)) @ a, b, atol=1e-9)
    assert np.array_equal(rotation_between([0.0, 0.0, 2.0], [0.0, 0.0, 1.0]), np.zeros(3))
    assert abs(rotation_between([0.0, 1.0, 0.0], [0.0, 0.0, 1.0])[2]) < 1e-12  # normal to both: none about the vertical


# The wrist wound towards its limits at the end of a scoop (joints 6 and 7 of the oracle's fudge,
# low, trial 3 under scoop-v10, whose lift with the scoop's heading the arm could not follow).
WOUND = np.array([-0.2, 0.18, -0.325, -2.363, -1.683, 3.582, 1.951])
PIVOT = np.array([0.0, 0.05, 0.1])  # a point in the grasp frame, as the spoon's centre is


def _limit_cost(kin, q):
    lower, upper = np.array(kin.lower[:7]), np.array(kin.upper[:7])
    return float(np.sum(((q - (lower + upper) / 2) / (upper - lower)) ** 2))


def test_a_heading_free_solve_holds_the_point_and_tilt_and_unwinds_towards_mid_range(kin):
    target = kin.forward(WOUND)
    q, residual = kin.solve_heading_free(target, WOUND, PIVOT, FINE_IK, limit_step=0.03)
    assert np.linalg.norm(residual[:3]) < FINE_IK.position and np.linalg.norm(residual[3:]) < FINE_IK.orientation
    reached = kin.forward(q)
    assert np.allclose(reached[:3, :3] @ PIVOT + reached[:3, 3], target[:3, :3] @ PIVOT + target[:3, 3], atol=1e-5)
    up = np.array([0.0, 0.0, 1.0])
    assert np.allclose(reached[:3, :3].T @ up, target[:3, :3].T @ up, atol=1e-5)  # the same tilt
    assert 0.005 < np.abs(q - WOUND).max() <= 0.03 + 1e-3  # one bounded step of self-motion
    assert _limit_cost(kin, q) < _limit_cost(kin, WOUND)
    # Repeated, the arm keeps moving away from its limits: the heading is what it gives up.
    for _ in range(30):
        q, residual = kin.solve_heading_free(target, q, PIVOT, FINE_IK, limit_step=0.03)
    assert _limit_cost(kin, q) < 0.8 * _limit_cost(kin, WOUND)
    heading = lambda m: np.arctan2(m[1, 0], m[0, 0])  # noqa: E731
    assert abs(heading(kin.forward(q)) - heading(target)) > 0.05


def test_without_the_limit_step_a_heading_free_solve_of_the_arms_own_pose_does_not_move(kin):
    q, residual = kin.solve_heading_free(kin.forward(WOUND), WOUND, PIVOT, FINE_IK, limit_step=0.0)
    assert np.allclose(q, WOUND, atol=1e-6) and np.abs(residual).max() < 1e-5


def test_a_heading_free_solve_stays_inside_the_joint_limits_for_a_point_out_of_reach(kin):
    target = kin.forward(WOUND)
    target[:3, 3] = [1.6, 0.0, 0.4]
    q, residual = kin.solve_heading_free(target, WOUND, PIVOT, FINE_IK, iterations=60)
    assert np.all(q >= np.array(kin.lower[:7]) - 1e-12) and np.all(q <= np.array(kin.upper[:7]) + 1e-12)
    assert np.linalg.norm(residual[:3]) > 0.3
