"""Stages 2 and 3 of the task: locate the target bowl from the cameras, carry the spoon there without collision, pour.

Localization uses perception only (no ground truth): the target bowl's pixels (segmentation) are
back-projected to world points, the points near the top of the bowl (its rim) are fitted with a
circle by least squares, and the rim height is the top of the points. The cameras see an arc of
the rim, which a circle fit handles, unlike a centroid of the visible points (biased towards the
cameras).

The path keeps the spoon level (no tilt, so the load stays in it) and goes up, across and down:
lift to a safe height above every obstacle's top (bowl rims, with `clearance`) while turning the
spoon level over `level_steps` actions (the scoop ends tipped up; turning it level in one
action asks the arm for a jump it answers by swinging to another elbow posture, which throws
the load), travel in a
straight line at that height (turning the spoon, level, to point away from the robot's base over
the target when asked: keeping the scoop's heading twists the wrist to its joint limit for
targets off to the side), descend to the pour height above the target's rim. It is checked
against the obstacles' bounding cylinders before it is executed. The pour rolls the spoon about
its own x axis above the target's centre, then the spoon holds still while the food settles.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from grits_lab.errors import InputError
from grits_lab.geometry import matrix_to_rot6d, rot6d_to_matrix
from grits_lab.sim.env import interpolate_pose


@dataclass
class BowlEstimate:
    centre: np.ndarray  # (3,) world: centre of the bowl's bottom (x, y) at table height (z)
    rim_radius: float
    rim_height: float  # world z of the rim
    n_points: int
    residual: float  # RMS of the circle fit, metres


def fit_circle(xy: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares circle (Kasa fit) through (M, 2) points: (centre (2,), radius, RMS residual)."""
    a = np.column_stack([2 * xy[:, 0], 2 * xy[:, 1], np.ones(len(xy))])
    b = (xy ** 2).sum(axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(a, b, rcond=None)
    r = math.sqrt(max(c + cx * cx + cy * cy, 0.0))
    residual = float(np.sqrt(np.mean((np.linalg.norm(xy - [cx, cy], axis=1) - r) ** 2)))
    return np.array([cx, cy]), r, residual


def locate_bowl(points: np.ndarray, table_height: float = 0.0, rim_band: float = 0.012) -> BowlEstimate:
    """Estimate a round bowl's centre and rim from its visible points (M, 3), world frame."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 20:
        raise InputError(f"the target bowl is not visible to the cameras ({len(pts)} points)")
    top = float(np.percentile(pts[:, 2], 99.5))
    rim = pts[pts[:, 2] > top - rim_band]
    if len(rim) < 10:
        rim = pts
    centre, radius, residual = fit_circle(rim[:, :2])
    return BowlEstimate(np.array([centre[0], centre[1], table_height]), radius, top, len(pts), residual)


def level_rotation(pose9: np.ndarray) -> np.ndarray:
    """(3, 3) the spoon held level (its z up) with the heading of `pose9` kept."""
    heading = rot6d_to_matrix(np.asarray(pose9[3:9], dtype=np.float64))[:2, 0]
    return heading_rotation(math.atan2(heading[1], heading[0]) if np.linalg.norm(heading) > 1e-6 else 0.0)


def heading_rotation(yaw: float) -> np.ndarray:
    """(3, 3) the level spoon pointing along world heading `yaw` (radians)."""
    x = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    return np.stack([x, np.cross(z, x), z], axis=1)


def _pose(position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    return np.concatenate([position, matrix_to_rot6d(rotation)]).astype(np.float32)


def _line(a: np.ndarray, b: np.ndarray, rotation: np.ndarray, max_step: float, end_rotation: np.ndarray | None = None,
          min_steps: int = 1) -> list[np.ndarray]:
    """Waypoints from a to b (a excluded) at most `max_step` apart (and at least `min_steps` of them),
    turning from `rotation` to `end_rotation` (slerp) on the way when it is given."""
    n = max(min_steps, int(math.ceil(np.linalg.norm(b - a) / max_step)))
    m0, m1 = np.eye(4), np.eye(4)
    m0[:3, :3], m1[:3, :3] = rotation, rotation if end_rotation is None else end_rotation
    return [_pose(a + (b - a) * (i / n), interpolate_pose(m0, m1, i / n)[:3, :3]) for i in range(1, n + 1)]


@dataclass
class Obstacle:
    """A vertical cylinder the spoon must stay above (bowls), world frame."""

    centre_xy: np.ndarray
    radius: float
    top: float


def path_is_clear(path: np.ndarray, obstacles: list[Obstacle], spoon_reach: float, start_index: int = 0) -> bool:
    """True when every waypoint from `start_index` on keeps the spoon (a sphere of `spoon_reach`
    around its centre) above every obstacle cylinder it passes over."""
    for pose in path[start_index:]:
        for ob in obstacles:
            if np.linalg.norm(pose[:2] - ob.centre_xy) < ob.radius + spoon_reach and pose[2] - spoon_reach < ob.top:
                return False
    return True


def plan_transfer(current: np.ndarray, target: BowlEstimate, obstacles: list[Obstacle], clearance: float,
                  pour_height: float, max_step: float, spoon_reach: float, level_steps: int = 1,
                  target_heading: float | None = None, level_yaw_offset: float = 0.0, pour_offset: float = 0.0) -> np.ndarray:
    """(T, 9) spoon path: up to a safe height while levelling over `level_steps` actions, across, down to
    `pour_height` above the target's rim, level from the end of the lift on.

    level_yaw_offset: radians the level spoon's heading is turned from the scoop's during the lift;
    pour_offset: metres the pour point moves from the target's centre away from the robot's base
    (at the world origin), which the arm reaches more easily for bowls close to it.
    """
    rotation = level_rotation(current)
    if level_yaw_offset:
        rotation = heading_rotation(math.atan2(rotation[1, 0], rotation[0, 0]) + level_yaw_offset)
    start = np.asarray(current[:3], dtype=np.float64)
    safe_z = max([start[2]] + [ob.top + clearance + spoon_reach for ob in obstacles])
    centre = np.asarray(target.centre[:2], dtype=np.float64)
    if pour_offset:
        centre = centre + pour_offset * centre / max(float(np.linalg.norm(centre)), 1e-9)
    above_target = np.array([centre[0], centre[1], safe_z])
    pour_point = np.array([centre[0], centre[1], target.rim_height + pour_height])
    tipped = rot6d_to_matrix(np.asarray(current[3:9], dtype=np.float64))
    waypoints = _line(start, np.array([start[0], start[1], safe_z]), tipped, max_step, rotation, level_steps)
    lifted = len(waypoints) - 1  # the vertical lift leaves the source bowl by design
    arrival = rotation if target_heading is None else heading_rotation(target_heading)
    waypoints += _line(waypoints[-1][:3].astype(np.float64), above_target, rotation, max_step, arrival)
    waypoints += _line(above_target, pour_point, arrival, max_step)
    path = np.stack(waypoints)
    # The lift starts in the source bowl and the descent ends in the target's cylinder by design:
    # check the way between them.
    others = [ob for ob in obstacles if np.linalg.norm(ob.centre_xy - target.centre[:2]) > 1e-3]
    if not path_is_clear(path, others, spoon_reach, start_index=lifted):
        raise InputError("no collision-free transfer path at the configured clearance")
    return path


def pour_motion(pose: np.ndarray, angle_deg: float, steps: int) -> np.ndarray:
    """(steps, 9) roll the spoon about its own x axis by `angle_deg`, in place."""
    rot = rot6d_to_matrix(np.asarray(pose[3:9], dtype=np.float64))
    out = []
    for i in range(1, steps + 1):
        a = math.radians(angle_deg) * i / steps
        roll = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
        out.append(_pose(np.asarray(pose[:3], dtype=np.float64), rot @ roll))
    return np.stack(out)


@dataclass(frozen=True)
class TransferOption:
    """One way of carrying the spoon: the lift's levelling (actions, heading turn in degrees) and the pour (height, offset, m)."""

    level_steps: int
    level_yaw_deg: float
    pour_height: float
    pour_offset: float

    def describe(self) -> str:
        return (f"level over {self.level_steps} actions, heading {self.level_yaw_deg:+g} deg; "
                f"pour {self.pour_height * 100:g} cm above the rim, {self.pour_offset * 100:+g} cm out")


@dataclass
class TransferPlan:
    """The chosen transfer: path (T, 9) up to the pour point, pour (P, 9), the option that made them,
    whether the check passed (`reachable`), how many options were checked (`n_checks`, 0 unchecked)."""

    path: np.ndarray
    pour: np.ndarray
    option: TransferOption
    reachable: bool
    n_checks: int


def transfer_options(settings: Any) -> list[TransferOption]:
    """The options to try, in order: the configured one first; lifts keep the scoop's heading before
    they turn it, and level over the configured actions before the alternatives; each lift with the
    configured pour first, then the pour alternatives (`TransferSettings`, evaluation_config.py)."""
    lifts = [(n, y) for y, n in itertools.product([0.0] + list(settings.alternative_level_yaw_deg),
                                                  [settings.level_steps] + list(settings.alternative_level_steps))]
    pours = [(h, o) for h, o in itertools.product([settings.pour_height] + list(settings.alternative_pour_heights),
                                                  [0.0] + list(settings.alternative_pour_offsets))]
    seen, out = set(), []
    for (n, y), (h, o) in itertools.product(lifts, pours):
        option = TransferOption(int(n), float(y), float(h), float(o))
        if option not in seen:
            seen.add(option)
            out.append(option)
    return out


def choose_transfer(current: np.ndarray, target: BowlEstimate, obstacles: list[Obstacle], settings: Any, max_step: float,
                    spoon_reach: float, target_heading: float | None,
                    check: Callable[[np.ndarray], Any] | None) -> TransferPlan:
    """Plan the transfer and pour, checked for reach when `check` is given.

    check(actions (T, 9)) -> a `PathCheck` (grits_lab.sim.env.ScoopEnv.check_path): per action,
    whether the arm cannot reach it and how far it steps a joint (rad). An option passes when no
    action steps a joint more than `settings.max_joint_step` and none after the first is
    unreachable (the first starts from the scoop's last command, which the arm may have stopped
    short of). The first option (`transfer_options`) that passes is taken; a lift that fails
    before the spoon leaves the vertical lift skips its other pours. After `settings.max_checks`
    checks without a pass, the option with the smallest joint step (no smaller than the limit),
    then the fewest unreachable actions, is taken, with `reachable` False.
    """
    best: tuple[tuple[float, int], TransferPlan] | None = None
    n_checks, failed_lift = 0, None
    for option in transfer_options(settings):
        if failed_lift == (option.level_steps, option.level_yaw_deg):
            continue
        path = plan_transfer(current, target, obstacles, settings.clearance, option.pour_height, max_step, spoon_reach,
                             option.level_steps, target_heading, math.radians(option.level_yaw_deg), option.pour_offset)
        pour = pour_motion(path[-1], settings.pour_angle_deg, settings.pour_steps)
        if check is None:
            return TransferPlan(path, pour, option, reachable=True, n_checks=0)
        answer = check(np.concatenate([path, pour]))
        n_checks += 1
        bad = answer.unreachable.copy()
        bad[0] = False
        bad |= answer.joint_steps > settings.max_joint_step
        plan = TransferPlan(path, pour, option, not bad.any(), n_checks)
        if plan.reachable:
            return plan
        key = (max(float(answer.joint_steps.max()), settings.max_joint_step), int(answer.unreachable[1:].sum()))
        if best is None or key < best[0]:
            best = (key, plan)
        if int(np.argmax(bad)) < _lift_length(path):
            failed_lift = (option.level_steps, option.level_yaw_deg)
        if n_checks >= settings.max_checks:
            break
    assert best is not None
    best[1].n_checks = n_checks
    return best[1]


def _lift_length(path: np.ndarray) -> int:
    """Actions at the start of `path` that rise straight up from where the spoon was."""
    xy = path[0, :2]
    n = 0
    for pose in path:
        if np.linalg.norm(pose[:2] - xy) > 1e-6:
            break
        n += 1
    return n
