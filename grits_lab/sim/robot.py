"""The Franka Panda with the spoon in its hand: IK on a private kinematic copy, joint position control.

IK runs on a second, kinematics-only PyBullet client holding just the Panda, so solving and
checking a pose (forward kinematics of the solution) never disturbs the simulated world. A pose
whose IK residual exceeds the tolerance is an IK failure: the arm keeps its last reachable joint
target (as a real controller rejects an unreachable goal) and the failure is counted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as pb
import pybullet_data
from pybullet_utils.bullet_client import BulletClient

from grits_lab.geometry import matrix_to_quat, quat_to_matrix, rotation_between, rotation_vector, skew
from grits_lab.sim.bullet import connect_direct
from grits_lab.sim.shapes import SpoonGeometry

PANDA_URDF = "franka_panda/panda.urdf"
ARM_JOINTS = tuple(range(7))
FINGER_JOINTS = (9, 10)
GRASP_LINK = 11  # panda_grasptarget
ARM_FORCES = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
# The arm motors' position gain per second. Bullet's position motor asks each step for the joint
# velocity positionGain * (target - angle) / time_step, so a gain fixed per step would correct an
# error twice as fast at half the step, another controller for every `sim.time_step`; per second it
# is one law at every step: 0.3 at 1/120 s, as always.
ARM_POSITION_GAIN_PER_S = 36.0
# Links -1 (base) to this one stand on the table by design: neither a collision nor a contact of the arm.
LAST_LINK_ON_TABLE = 1
# The Panda's joint velocity limits, rad/s (Franka Control Interface documentation, "Robot and
# interface specifications", limits in joint space: q_dot_max).
PANDA_MAX_JOINT_VELOCITY = (2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100)
# Damped least squares (`PandaKinematics.refine`): damping (the smallest singular value of J it
# still inverts as if full, about), the most one iteration moves a joint (rad), iterations at most.
DLS_DAMPING = 0.02
DLS_MAX_STEP = 0.2
DLS_ITERATIONS = 300
# `PandaKinematics.solve_heading_free`: the most its null-space step away from the joint limits moves
# a joint per solve (rad): at one solve per 0.1 s action, 0.3 rad/s, an eighth of the Panda's limits.
LIMIT_AVOID_STEP = 0.03
# A comfortable configuration with the hand pointing forward and down: the IK null-space target.
REST_POSE = (0.0, 0.2, 0.0, -2.0, 0.0, 2.6, 0.785)


def joint_speed_ratio(joint_step: np.ndarray, control_hz: float) -> float:
    """max_j |joint_step_j| / (PANDA_MAX_JOINT_VELOCITY_j / control_hz) for one action's change of
    the 7 arm joints (rad): above 1, no Panda moves that far in one control period."""
    limit = np.asarray(PANDA_MAX_JOINT_VELOCITY) / float(control_hz)
    return float(np.max(np.abs(np.asarray(joint_step, dtype=np.float64)[:7]) / limit))


def slowed_steps(joint_step: np.ndarray, steps: int, time_step: float, cap: float | None) -> int:
    """Physics steps (>= `steps`) over which the arm may move its joint targets by `joint_step` (7,)
    rad without any joint exceeding `cap` x its Panda limit (PANDA_MAX_JOINT_VELOCITY, rad/s);
    `time_step` in seconds. None: `steps`, whatever the speed (SimConfig.joint_speed_cap)."""
    if cap is None:
        return steps
    needed = joint_speed_ratio(joint_step, 1.0 / (float(cap) * float(time_step)))  # physics steps at the capped limits
    return max(int(steps), int(math.ceil(needed - 1e-9)))


def dls_step(rows: np.ndarray, error: np.ndarray, joints: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Joints (7,) one damped least-squares iteration from `joints` along a task's Jacobian rows (K, 7)
    towards its error (K,): dq = J^T (J J^T + DLS_DAMPING^2 I)^-1 e, scaled so that no joint moves
    more than DLS_MAX_STEP rad, clipped to the joint limits `lower`, `upper` (7,)."""
    dq = rows.T @ np.linalg.solve(rows @ rows.T + DLS_DAMPING**2 * np.eye(len(rows)), error)
    return np.clip(joints + dq * min(1.0, DLS_MAX_STEP / max(float(np.abs(dq).max()), 1e-12)), lower, upper)


def pose_to_matrix(position: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(np.asarray(quat_xyzw, dtype=np.float64))
    m[:3, 3] = position
    return m


def matrix_to_pose(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return m[:3, 3].copy(), matrix_to_quat(m[:3, :3])


def spoon_in_hand(spoon: SpoonGeometry) -> np.ndarray:
    """(4, 4) pose of the hand's grasp frame in the spoon frame."""
    m = np.eye(4)
    m[:3, :3] = spoon.hand_from_spoon_rotation()
    m[:3, 3] = spoon.grasp_point()
    return m


@dataclass
class IKResult:
    joints: np.ndarray  # (7,)
    position_error: float
    orientation_error: float
    ok: bool

    @property
    def miss(self) -> float:
        """How far the answer lands from the pose, as `solve` ranks answers: metres plus 0.05 m per radian."""
        return self.position_error + 0.05 * self.orientation_error


@dataclass(frozen=True)
class IKConvergence:
    """When an IK solve stops refining: the residual below `position` (m) and `orientation` (rad),
    or after `attempts` calls of PyBullet's solver, each refining the last answer."""

    position: float
    orientation: float
    attempts: int

    def reached(self, position_error: float, orientation_error: float) -> bool:
        return position_error < self.position and orientation_error < self.orientation


# COARSE_IK: one solve per 25 ms piece (the scoop's actions). FINE_IK: one solve per physics step
# (`ScoopEnv.step_along`), where a residual of 0.1 mm between consecutive targets is 1.4 m/s^2 of
# jitter at 120 Hz.
COARSE_IK = IKConvergence(1e-4, 1e-3, attempts=4)
FINE_IK = IKConvergence(1e-6, 1e-5, attempts=8)
# A heading-free lift's action counts as reached (`ScoopEnv.heading_free_path`) within 1 mm of its
# centre and 0.01 rad of its tilt (`attempts` unused).
HEADING_FREE_TOLERANCE = IKConvergence(1e-3, 1e-2, attempts=1)


class PandaKinematics:
    """IK and forward kinematics of the Panda's grasp frame, on its own DIRECT client."""

    def __init__(self, base_position: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.client = connect_direct()
        self.client.setAdditionalSearchPath(pybullet_data.getDataPath())
        self.robot = self.client.loadURDF(PANDA_URDF, base_position, useFixedBase=True)
        self.lower, self.upper = [], []
        for j in range(self.client.getNumJoints(self.robot)):
            info = self.client.getJointInfo(self.robot, j)
            if info[2] != pb.JOINT_FIXED:
                self.lower.append(info[8])
                self.upper.append(info[9])
        self.ranges = [u - l for l, u in zip(self.lower, self.upper)]
        self.rest = list(REST_POSE) + [0.006, 0.006]
        self._table, self._obstacles = -1, []  # static bodies the arm must not touch (`set_obstacles`)

    def set_obstacles(self, table: int, others: list[int]) -> None:
        """Static bodies already built in `self.client` that the arm must not touch; the previous
        ones are removed. The table is touched by the links up to LAST_LINK_ON_TABLE by design."""
        for body in self._obstacles:
            self.client.removeBody(body)
        self._table, self._obstacles = table, [table, *others]

    def touches_obstacles(self, joints: np.ndarray, margin: float) -> bool:
        """Whether the arm at joints (7,) comes within `margin` metres of an obstacle (`set_obstacles`)."""
        self.set_joints(joints)
        for body in self._obstacles:
            for point in self.client.getClosestPoints(self.robot, body, margin):
                if body != self._table or point[3] > LAST_LINK_ON_TABLE:
                    return True
        return False

    def set_joints(self, joints: np.ndarray) -> None:
        for j, q in zip(ARM_JOINTS, joints):
            self.client.resetJointState(self.robot, j, float(q))

    def forward(self, joints: np.ndarray) -> np.ndarray:
        """(4, 4) grasp-frame pose for arm joints (7,)."""
        self.set_joints(joints)
        state = self.client.getLinkState(self.robot, GRASP_LINK, computeForwardKinematics=True)
        return pose_to_matrix(np.array(state[4]), np.array(state[5]))

    def jacobian(self, joints: np.ndarray) -> np.ndarray:
        """(6, 7) geometric Jacobian of the grasp frame at arm joints (7,): rows linear (m/rad) then
        angular (rad/rad) velocity in the world frame (PyBullet's calculateJacobian)."""
        q = [float(v) for v in joints[:7]] + list(self.rest[7:])  # the fingers as the arm holds them
        linear, angular = self.client.calculateJacobian(self.robot, GRASP_LINK, [0.0, 0.0, 0.0], q, [0.0] * 9, [0.0] * 9)
        return np.vstack([np.asarray(linear)[:, :7], np.asarray(angular)[:, :7]])

    def residual(self, target: np.ndarray, joints: np.ndarray) -> np.ndarray:
        """(6,) what separates the grasp frame at joints (7,) from a (4, 4) target: position (m), then
        the rotation taking it to the target as an axis-angle vector (rad), both in the world frame."""
        reached = self.forward(joints)
        return np.concatenate([target[:3, 3] - reached[:3, 3], rotation_vector(target[:3, :3] @ reached[:3, :3].T)])

    def refine(self, target: np.ndarray, seed_joints: np.ndarray, converged: IKConvergence = FINE_IK,
               iterations: int = DLS_ITERATIONS) -> np.ndarray:
        """Joints (7,) from `seed_joints` towards a (4, 4) grasp-frame target by damped least squares
        (dq = J^T (J J^T + DLS_DAMPING^2 I)^-1 e; Wampler 1986, Buss 2004), every iterate clipped to
        the joint limits and no joint moved more than DLS_MAX_STEP rad per iteration, until the
        residual is within `converged` or after `iterations`. No earlier stop: on a lift the scoop-v9
        oracle held, the residual shrank by less than 0.1 % an iteration for 30 iterations in a row
        before it converged, and stopping there left the lift unreachable. Every step is the least
        joint motion towards the pose, so the arm follows it from where it is and never jumps to
        another posture."""
        lower, upper = np.asarray(self.lower[:7]), np.asarray(self.upper[:7])
        q = np.clip(np.asarray(seed_joints, dtype=np.float64)[:7], lower, upper)
        for _ in range(iterations):
            e = self.residual(target, q)
            if converged.reached(float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:]))):
                break
            q = dls_step(self.jacobian(q), e, q, lower, upper)
        return q

    def solve_heading_free(self, target: np.ndarray, seed_joints: np.ndarray, pivot: np.ndarray,
                           converged: IKConvergence = FINE_IK, limit_step: float = LIMIT_AVOID_STEP,
                           iterations: int = DLS_ITERATIONS) -> tuple[np.ndarray, np.ndarray]:
        """Joints (7,) that hold a point and the tilt of a (4, 4) grasp-frame target, its heading about
        the world's vertical left free, from `seed_joints`; and the 5 residuals there (m, m, m, rad, rad).

        pivot: (3,) the point, in the grasp frame, whose world position is held (the spoon's centre:
        turning the spoon's heading about its centre keeps its load where it is). The task is five-
        dimensional: the pivot's position and where the world's vertical lies in the grasp frame
        (the tilt, two angles); a rotation about the world's vertical through the pivot changes
        neither. The arm's seven joints then leave a two-dimensional null space instead of one,
        and the solver spends it on moving away from the joint limits: first one step down the
        gradient of H(q) = sum_j ((q_j - mid_j) / range_j)^2 / 2, projected onto the task's null
        space (Liegeois 1977), with unit gain and no joint moved more than `limit_step` rad (so the
        step vanishes where H is least on the null space), then damped least squares on the five task rows
        (`refine`'s iteration, Wampler 1986) until the residual is within `converged` or after
        `iterations`. Every iterate is clipped to the joint limits."""
        lower, upper = np.asarray(self.lower[:7]), np.asarray(self.upper[:7])
        mid, span = (lower + upper) / 2, upper - lower
        pivot = np.asarray(pivot, dtype=np.float64)
        goal = target[:3, :3] @ pivot + target[:3, 3]
        up_in_grasp = target[:3, :3].T @ np.array([0.0, 0.0, 1.0])

        def task(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            reached = self.forward(q)
            r = reached[:3, :3] @ pivot
            w = reached[:3, :3] @ up_in_grasp  # where the target's vertical lies now; held, it is the world's
            tilt = rotation_between(w, np.array([0.0, 0.0, 1.0]))
            jac = self.jacobian(q)
            rows = np.vstack([jac[:3] - skew(r) @ jac[3:], jac[3:5]])  # the pivot's velocity; tilting about world x, y
            return np.concatenate([goal - (reached[:3, 3] + r), tilt[:2]]), rows

        q = np.clip(np.asarray(seed_joints, dtype=np.float64)[:7], lower, upper)
        if limit_step > 0:
            _, rows = task(q)
            inverse = rows.T @ np.linalg.inv(rows @ rows.T + DLS_DAMPING**2 * np.eye(5))
            away = -(np.eye(7) - inverse @ rows) @ ((q - mid) / span**2)  # rad per unit gain: vanishes at the optimum
            q = np.clip(q + away * min(1.0, limit_step / max(float(np.abs(away).max()), 1e-12)), lower, upper)
        for _ in range(iterations):
            e, rows = task(q)
            if converged.reached(float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:]))):
                return q, e
            q = dls_step(rows, e, q, lower, upper)
        return q, task(q)[0]

    def solve(self, target: np.ndarray, seed_joints: np.ndarray, pos_tol: float, rot_tol: float, rest_pull: bool = True,
              converged: IKConvergence = COARSE_IK, refine: bool = False) -> IKResult:
        """IK for a (4, 4) grasp-frame target, starting from `seed_joints`; checks the residual by FK.

        converged: when the solve stops refining (`IKConvergence`: `COARSE_IK`, `FINE_IK`).
        refine: when PyBullet's answer is out of tolerance (`pos_tol`, `rot_tol`: an IK failure),
        also `refine` from `seed_joints` and keep whichever lands closer; an answer within tolerance
        stands as it is, so a motion PyBullet's solver follows is followed the same way. (Refining
        every answer short of `converged` instead found, from some seeds, a far posture closer to
        the pose: a joint jump that failed options PyBullet's answer had passed.) PyBullet's solver,
        seeded at an arm far from its rest posture, can stall centimetres short of a pose the arm
        reaches by moving on from where it is (3 of the scoop-v9 oracle's 9 held transfers: the lift
        stalled 1-4 cm up with no joint at its limit); the damped least-squares iterations move on.

        rest_pull: the first solve pulls the arm towards REST_POSE in the null space (a natural elbow);
        False: every solve only refines from `seed_joints`, so the arm follows a path with the least
        joint motion and no self-motion (a redundant arm far from its rest posture otherwise swings
        its shoulder and upper arm against each other in one step, whatever the step's size).
        """
        position, quat = matrix_to_pose(target)
        self.set_joints(seed_joints)
        best = None
        for attempt in range(converged.attempts):
            # The first solve pulls towards the rest pose (null space) to keep a natural elbow;
            # later ones refine from the previous solution without it, which reaches poses the
            # null-space pull would stop short of.
            extra = dict(lowerLimits=self.lower, upperLimits=self.upper, jointRanges=self.ranges, restPoses=self.rest) if attempt == 0 and rest_pull else {}
            sol = self.client.calculateInverseKinematics(
                self.robot, GRASP_LINK, position.tolist(), quat.tolist(), maxNumIterations=100, residualThreshold=1e-5, **extra,
            )
            joints = np.clip(np.array(sol[:7]), self.lower[:7], self.upper[:7])
            reached = self.forward(joints)
            perr = float(np.linalg.norm(reached[:3, 3] - position))
            rdiff = reached[:3, :3].T @ target[:3, :3]
            rerr = float(math.acos(np.clip((np.trace(rdiff) - 1) / 2, -1.0, 1.0)))
            answer = IKResult(joints, perr, rerr, perr <= pos_tol and rerr <= rot_tol)
            if best is None or answer.miss < best.miss:
                best = answer
            if converged.reached(perr, rerr):
                break
        assert best is not None
        if refine and not best.ok:
            joints = self.refine(target, seed_joints, converged)
            e = self.residual(target, joints)
            perr, rerr = float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:]))
            answer = IKResult(joints, perr, rerr, perr <= pos_tol and rerr <= rot_tol)
            if answer.miss < best.miss:
                best = answer
        return best

    def close(self) -> None:
        try:
            self.client.disconnect()
        except pb.error:
            pass
