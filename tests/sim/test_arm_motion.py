"""The arm as a robot moves it: joint targets streamed smoothly (SimConfig.joint_command), and
contacts of the arm itself with the table and the bowls, measured in the world and foreseen on the
kinematic copy."""

from __future__ import annotations

import numpy as np
import pytest

from grits_lab.sim import ScoopEnv, SimConfig
from grits_lab.sim.env import ARM_CLEARANCE, matrix_to_pose9


def spoon_accelerations(joint_command: str) -> np.ndarray:
    """|a| (m/s^2) of the spoon at every physics step while it is commanded along a straight line
    at a constant 0.1 m/s (after one action to get going), with no food in the world."""
    env = ScoopEnv(SimConfig(joint_command=joint_command))
    try:
        env.reset(seed=0, options={"food": "soybeans", "n_particles": 0})
        start = matrix_to_pose9(env.spoon_pose())
        end = start.copy()
        end[0] -= 0.2  # 20 cm at 1 cm per 0.1 s action
        path = np.linspace(start, end, 21)[1:]
        world = env.world
        speeds = []
        original = world.step

        def step(n: int = 1) -> None:
            for _ in range(n):
                original(1)
                speeds.append(np.array(world.client.getBaseVelocity(world.spoon)[0]))

        world.step = step
        for action in path:
            env.step(action)
        v = np.array(speeds)
        return np.linalg.norm(np.diff(v, axis=0), axis=1)[2 * env.config.substeps:] / env.config.time_step
    finally:
        env.close()


def test_a_constant_velocity_command_moves_the_spoon_without_lurching():
    smooth = spoon_accelerations("interpolated")
    lurching = spoon_accelerations("stepwise")
    # A steady 0.1 m/s line asks for no acceleration: the streamed targets keep the spoon near it,
    # where holding each IK solution with a zero velocity target stops and starts it every 25 ms.
    assert np.percentile(smooth, 95) < 0.5
    assert np.median(lurching) > 5 * np.median(smooth)


@pytest.fixture(scope="module")
def env():
    e = ScoopEnv()
    e.reset(seed=0, options={"food": "soybeans", "n_particles": 0})
    yield e
    e.close()


def test_the_arm_at_its_start_touches_nothing_and_pressed_to_the_table_it_does(env):
    joints = env._joint_target.copy()
    assert not env.kinematics.touches_obstacles(joints, ARM_CLEARANCE)
    assert not env.world.arm_touches_static()
    bent = joints.copy()
    bent[1] += 1.2  # the shoulder pitched forward: the hand goes down through the table
    assert env.kinematics.touches_obstacles(bent, ARM_CLEARANCE)


def test_a_path_through_the_table_is_foreseen_on_the_kinematic_copy(env):
    start = matrix_to_pose9(env.spoon_pose())
    low = start.copy()
    low[2] = -0.2  # the spoon's frame 20 cm below the table's top: the hand holding it is in the table
    assert env.check_path(np.linspace(start, low, 8)).touches is None  # only checked when asked
    check = env.check_path(np.linspace(start, low, 8), touches=True)
    assert not check.unreachable.any()  # the arm can reach it; only the table is in the way
    assert not check.touches[0] and check.touches[-1]
