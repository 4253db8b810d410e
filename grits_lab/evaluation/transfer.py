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
against the obstacles' bounding cylinders before it is executed. The pour turns the spoon above
the target's centre, about its own x axis (`pour_axis: roll`, food leaves over the side lip) or
about its tip (`pour_axis: tip`, food slides off the lipless tip), then the spoon holds still while
the food settles.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from grits_lab.errors import InputError
from grits_lab.geometry import axis_angle_matrix, matrix_to_rot6d, rot6d_to_matrix
from grits_lab.sim.env import interpolate_pose, matrix_to_pose9, pose9_to_matrix


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


def min_jerk(n: int) -> np.ndarray:
    """(n,) fractions of a rest-to-rest move after each of n equal time steps, on the minimum-jerk
    profile s(u) = 10u^3 - 15u^4 + 6u^5 (Flash & Hogan 1985): zero velocity and acceleration at
    both ends, peak speed 1.875x the mean, peak acceleration 5.77 L / T^2."""
    u = np.arange(1, n + 1) / n
    return 10 * u**3 - 15 * u**4 + 6 * u**5


MIN_JERK_PEAK_SPEED = 1.875  # peak over mean speed of `min_jerk`


def profile_fractions(n: int, profile: str) -> np.ndarray:
    """(n,) fractions of a move done after each of its n actions: "min_jerk" (`min_jerk`) or equal steps."""
    return min_jerk(n) if profile == "min_jerk" else np.arange(1, n + 1) / n


def _line(a: np.ndarray, b: np.ndarray, rotation: np.ndarray, max_step: float, end_rotation: np.ndarray | None = None,
          min_steps: int = 1, profile: str = "constant") -> list[np.ndarray]:
    """Waypoints from a to b (a excluded), one per action, turning from `rotation` to `end_rotation`
    (slerp) on the way when it is given, in at least `min_steps` actions.

    profile "constant": equal steps of at most `max_step` (a jump from rest to full speed in one
    action); "min_jerk": rest to rest on the minimum-jerk profile with a peak step of at most
    `max_step` (the time-parameterization a motion planner gives a robot).
    """
    length = float(np.linalg.norm(b - a))
    peak = MIN_JERK_PEAK_SPEED if profile == "min_jerk" else 1.0
    n = max(min_steps, int(math.ceil(peak * length / max_step)))
    fractions = profile_fractions(n, profile)
    m0, m1 = np.eye(4), np.eye(4)
    m0[:3, :3], m1[:3, :3] = rotation, rotation if end_rotation is None else end_rotation
    return [_pose(a + (b - a) * f, interpolate_pose(m0, m1, f)[:3, :3]) for f in fractions]


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
                  target_heading: float | None = None, level_yaw_offset: float = 0.0, pour_offset: float = 0.0,
                  profile: str = "constant", lip_offset: float = 0.0, pour_axis: str = "roll") -> np.ndarray:
    """(T, 9) spoon path: up to a safe height while levelling over `level_steps` actions, across, down to
    `pour_height` above the target's rim (negative: into the bowl), level from the end of the lift on.
    The first `lift_length(path)` actions are the lift (they rise straight up); the rest the carry.

    level_yaw_offset: radians the level spoon's heading is turned from the scoop's during the lift;
    pour_offset: metres the pour point moves from the target's centre away from the robot's base
    (at the world origin), which the arm reaches more easily for bowls close to it; profile: each
    straight segment's time-parameterization (`_line`); lip_offset: metres the spoon's centre is
    moved at the pour so that the edge the food leaves by pours over the target's centre instead of
    2-3 cm from it: along the spoon's own +y axis for `pour_axis` "roll" (its -y lip, the one
    `pour_motion` lowers), along its -x axis for "tip" (its tip). InputError when the path would
    cross an obstacle.
    """
    lift = lift_path(current, obstacles, clearance, max_step, spoon_reach, level_steps, level_yaw_offset, profile)
    carry = carry_path(lift[-1], target, obstacles, safe_height(current, obstacles, clearance, spoon_reach), pour_height,
                       max_step, spoon_reach, target_heading, pour_offset, profile, lip_offset, pour_axis,
                       lifted_rotation(current, level_yaw_offset))
    return np.concatenate([lift, carry])


def safe_height(current: np.ndarray, obstacles: list[Obstacle], clearance: float, spoon_reach: float) -> float:
    """World z (m) the spoon's centre is lifted to from `current` (9,): `clearance` and `spoon_reach`
    above every obstacle's top, and never below where it is."""
    return max([float(current[2])] + [ob.top + clearance + spoon_reach for ob in obstacles])


def lift_path(current: np.ndarray, obstacles: list[Obstacle], clearance: float, max_step: float, spoon_reach: float,
              level_steps: int = 1, level_yaw_offset: float = 0.0, profile: str = "constant") -> np.ndarray:
    """(L, 9) the lift of `plan_transfer`: straight up from `current` (9,) to the safe height above every
    obstacle (`clearance` and `spoon_reach` over its top), turning the spoon from its tipped pose to
    level (its heading turned by `level_yaw_offset` rad) over at least `level_steps` actions."""
    rotation = lifted_rotation(current, level_yaw_offset)
    start = np.asarray(current[:3], dtype=np.float64)
    safe_z = safe_height(current, obstacles, clearance, spoon_reach)
    tipped = rot6d_to_matrix(np.asarray(current[3:9], dtype=np.float64))
    return np.stack(_line(start, np.array([start[0], start[1], safe_z]), tipped, max_step, rotation, level_steps, profile))


def lifted_rotation(current: np.ndarray, level_yaw_offset: float = 0.0) -> np.ndarray:
    """(3, 3) the level spoon at the top of `lift_path` from `current` (9,): the scoop's heading turned
    by `level_yaw_offset` rad."""
    rotation = level_rotation(current)
    if level_yaw_offset:
        rotation = heading_rotation(math.atan2(rotation[1, 0], rotation[0, 0]) + level_yaw_offset)
    return rotation


def carry_path(lifted: np.ndarray, target: BowlEstimate, obstacles: list[Obstacle], height: float, pour_height: float,
               max_step: float, spoon_reach: float, target_heading: float | None = None, pour_offset: float = 0.0,
               profile: str = "constant", lip_offset: float = 0.0, pour_axis: str = "roll",
               rotation: np.ndarray | None = None) -> np.ndarray:
    """(C, 9) the carry of `plan_transfer` from the lifted, level spoon `lifted` (9,): across at `height`
    (world z, m: the lift's `safe_height`) to above the pour point, turning to `target_heading` (None:
    keeping its heading), then down to it; the other arguments are `plan_transfer`'s. rotation: the
    lifted spoon's (3, 3) when it is known exactly (`lifted_rotation`; None: read from `lifted`, whose
    6-D rotation is single precision). InputError when it would cross an obstacle other than the
    target bowl (the source bowl, which the lift leaves by design, included)."""
    rotation = level_rotation(lifted) if rotation is None else rotation
    start = np.asarray(lifted[:3], dtype=np.float64)
    centre = np.asarray(target.centre[:2], dtype=np.float64)
    if pour_offset:
        centre = centre + pour_offset * centre / max(float(np.linalg.norm(centre)), 1e-9)
    arrival = rotation if target_heading is None else heading_rotation(target_heading)
    if lip_offset:
        centre = centre + lip_offset * (arrival[:2, 1] if pour_axis == "roll" else -arrival[:2, 0])
    above_target = np.array([centre[0], centre[1], height])
    pour_point = np.array([centre[0], centre[1], target.rim_height + pour_height])
    waypoints = _line(start, above_target, rotation, max_step, arrival, profile=profile)
    waypoints += _line(above_target, pour_point, arrival, max_step, profile=profile)
    path = np.stack(waypoints)
    # The descent ends in the target's cylinder by design: check the way there.
    others = [ob for ob in obstacles if np.linalg.norm(ob.centre_xy - target.centre[:2]) > 1e-3]
    if not path_is_clear(np.concatenate([np.asarray(lifted, dtype=np.float32)[None], path]), others, spoon_reach):
        raise InputError("no collision-free transfer path at the configured clearance")
    return path


def pour_motion(pose: np.ndarray, angle_deg: float, steps: int, profile: str = "constant", axis: str = "roll",
                tip: float = 0.0) -> np.ndarray:
    """(steps, 9) turn the spoon by `angle_deg` in `steps` actions (profile: "constant" equal
    increments, "min_jerk" from rest to rest, `min_jerk`).

    axis "roll": about the spoon's own x axis, in place. A positive angle raises the spoon's +y
    side: the food leaves over its -y lip. The hand, 11 cm above the spoon's bowl on the steep
    handle, swings down beside it: 6 cm below the bowl at 120 degrees.
    axis "tip": about the spoon's y axis through its tip, the point `tip` metres along its +x axis,
    which stays where it is. A positive angle lowers the tip: the food slides off the lipless tip
    while the handle, and the hand on it, rise over the spoon (at 90 degrees the grasp point is
    about 7 cm above the tip).
    """
    rot = rot6d_to_matrix(np.asarray(pose[3:9], dtype=np.float64))
    position = np.asarray(pose[:3], dtype=np.float64)
    pivot = position + rot[:, 0] * tip
    turns = axis_angle_matrix([1.0, 0.0, 0.0] if axis == "roll" else [0.0, 1.0, 0.0],
                              math.radians(angle_deg) * profile_fractions(steps, profile))
    out = []
    for turn in turns:
        turned = rot @ turn
        out.append(_pose(position if axis == "roll" else pivot - turned[:, 0] * tip, turned))
    return np.stack(out)


def slow_to_limits(start: np.ndarray, actions: np.ndarray, stages: list[str], check: Callable[[np.ndarray], Any],
                   max_slowdown: int, rounds: int = 3) -> tuple[np.ndarray, list[str], Any, bool]:
    """Slow a motion until no action asks a joint to move faster than the Panda can.

    start: (9,) the pose before the first action; actions: (T, 9); stages: (T,) each action's stage
    name; check: `ScoopEnv.check_path`. Every stage holding an action whose `speed_ratios` entry
    exceeds 1 is slowed as a whole by k = ceil(its largest ratio): each of its actions is cut into
    k actions on the same pose path, so the stage takes k times as long and keeps its velocity
    profile's shape (a min-jerk segment still starts and ends at rest). The motion is checked again,
    up to `rounds` times. A stage that would need more than `max_slowdown` times its planned
    duration holds a change of arm posture, which slowing cannot remove.
    Returns (actions, stages, the last check's answer, whether every action is within the limits).
    """
    slowdown = {stage: 1 for stage in stages}
    answer = check(actions)
    for _ in range(rounds):
        over = answer.speed_ratios > 1.0 + 1e-9
        if not over.any():
            return actions, stages, answer, True
        factor = {stage: 1 for stage in slowdown}
        for i in np.flatnonzero(over):
            factor[stages[i]] = max(factor[stages[i]], int(math.ceil(answer.speed_ratios[i] * 1.05)))
        if any(slowdown[st] * k > max_slowdown for st, k in factor.items()):
            return actions, stages, answer, False
        new_actions, new_stages, previous = [], [], pose9_to_matrix(start)
        for action, stage in zip(actions, stages):
            target = pose9_to_matrix(action)
            k = factor[stage]
            new_actions += [matrix_to_pose9(interpolate_pose(previous, target, j / k)).astype(np.float32) for j in range(1, k + 1)]
            new_stages += [stage] * k
            previous = target
        slowdown = {st: slowdown[st] * factor[st] for st in slowdown}
        actions, stages = np.stack(new_actions), new_stages
        answer = check(actions)
    return actions, stages, answer, not bool((answer.speed_ratios > 1.0 + 1e-9).any())


@dataclass(frozen=True)
class TransferOption:
    """One way of carrying the spoon: the lift's levelling (actions, heading turn in degrees) and the
    pour (height, offset, m; the spoon's heading there, degrees from the one `TransferSettings.heading` gives)."""

    level_steps: int
    level_yaw_deg: float
    pour_height: float
    pour_offset: float
    pour_yaw_deg: float = 0.0
    # The lift's heading left to the arm, which unwinds its wrist from its joint limits on the way up
    # (`ScoopEnv.heading_free_path`); the carry then starts from the heading the lift ends with.
    heading_free: bool = False

    def describe(self) -> str:
        yaw = f", turned {self.pour_yaw_deg:+g} deg" if self.pour_yaw_deg else ""
        heading = "heading free (wrist unwound)" if self.heading_free else f"heading {self.level_yaw_deg:+g} deg"
        return (f"level over {self.level_steps} actions, {heading}; "
                f"pour {self.pour_height * 100:g} cm above the rim, {self.pour_offset * 100:+g} cm out{yaw}")


@dataclass
class TransferPlan:
    """The chosen transfer: actions (T, 9) from the lift to the end of the pour, stages (T,) each
    action's stage ("lift", "carry", "pour"), the option that made them, whether the check passed
    (`reachable`: no unreachable pose after the first, no joint faster than the Panda's limit, or
    over `max_joint_step` without slowing), and how many paths were checked (`n_checks`, 0 unchecked)."""

    actions: np.ndarray
    stages: list[str]
    option: TransferOption
    reachable: bool
    n_checks: int

    @property
    def n_pour(self) -> int:
        return sum(stage == "pour" for stage in self.stages)


def transfer_options(settings: Any, heading_free: bool = False) -> list[TransferOption]:
    """The options to try, in order: the configured one first; lifts keep the scoop's heading before
    they turn it, and level over the configured actions before the alternatives; each lift with the
    configured pour first, then the pour alternatives, the pour's heading varying fastest
    (`TransferSettings`, grits_lab/task/transfer_settings.py). heading_free: the options whose lift
    leaves the heading to the arm instead (`TransferOption.heading_free`; no heading turns), in the
    same order, which `choose_transfer` tries when every option above has failed."""
    yaws = [0.0] if heading_free else [0.0] + list(settings.alternative_level_yaw_deg)
    lifts = [(n, y) for y, n in itertools.product(yaws, [settings.level_steps] + list(settings.alternative_level_steps))]
    pours = list(itertools.product([settings.pour_height] + list(settings.alternative_pour_heights),
                                   [0.0] + list(settings.alternative_pour_offsets),
                                   [settings.pour_yaw_deg] + list(settings.alternative_pour_yaw_deg)))
    seen, out = set(), []
    for (n, y), (h, o, w) in itertools.product(lifts, pours):
        option = TransferOption(int(n), float(y), float(h), float(o), float(w), heading_free)
        if option not in seen:
            seen.add(option)
            out.append(option)
    return out


# What a heading-free lift gives (`ScoopEnv.heading_free_path` through `choose_transfer`'s `heading_free`):
# for the lift's actions (L, 9), the spoon poses (L, 9) the arm reaches and whether each was reached.
HeadingFreeLift = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def option_motion(current: np.ndarray, target: BowlEstimate, obstacles: list[Obstacle], settings: Any, max_step: float,
                  spoon_reach: float, target_heading: float | None, option: TransferOption,
                  pour_edge: float = 0.0, heading_free: HeadingFreeLift | None = None
                  ) -> tuple[np.ndarray, list[str], bool]:
    """The actions (T, 9) of one option, lift to pour, each action's stage, and whether its lift was
    reached (always True but for a heading-free lift the arm could not follow). pour_edge: metres
    from the spoon's centre to the edge the food leaves by (its -y lip for `settings.pour_axis`
    "roll", its tip for "tip"); with `settings.pour_lip_over_centre` that edge pours over the
    target's centre. heading_free: how the arm lifts with its heading free, needed by an option
    with `heading_free` (ValueError without it): its lift is the poses the arm reaches holding the
    planned lift's centre and tilt with its heading left free (`ScoopEnv.heading_free_path`), and
    the carry starts from where that lift ends."""
    lip_offset = pour_edge if settings.pour_lip_over_centre else 0.0
    if target_heading is not None:
        target_heading += math.radians(option.pour_yaw_deg)
    lift = lift_path(current, obstacles, settings.clearance, max_step, spoon_reach, option.level_steps,
                     math.radians(option.level_yaw_deg), settings.profile)
    reached, rotation = True, lifted_rotation(current, math.radians(option.level_yaw_deg))
    if option.heading_free:
        if heading_free is None:
            raise ValueError("a heading-free option needs the arm's heading-free lift (`heading_free`)")
        lift, lift_reached = heading_free(lift)
        reached, rotation = bool(np.all(lift_reached)), level_rotation(lift[-1])
    height = safe_height(current, obstacles, settings.clearance, spoon_reach)
    carry = carry_path(lift[-1], target, obstacles, height, option.pour_height, max_step, spoon_reach,
                       target_heading, option.pour_offset, settings.profile, lip_offset, settings.pour_axis, rotation)
    pour = pour_motion(carry[-1], settings.pour_angle_deg, settings.pour_steps, settings.profile, settings.pour_axis,
                       tip=pour_edge)
    hold = np.repeat(lift[-1:], settings.lift_hold_steps, axis=0)  # the lifted spoon held still
    stages = ["lift"] * (len(lift) + len(hold)) + ["carry"] * len(carry) + ["pour"] * len(pour)
    return np.concatenate([lift, hold, carry, pour]).astype(np.float32), stages, reached


def choose_transfer(current: np.ndarray, target: BowlEstimate, obstacles: list[Obstacle], settings: Any, max_step: float,
                    spoon_reach: float, target_heading: float | None,
                    check: Callable[[np.ndarray], Any] | None, pour_edge: float = 0.0,
                    heading_free: HeadingFreeLift | None = None) -> TransferPlan:
    """Plan the transfer and pour, checked for reach (and slowed to the Panda's joint limits) when
    `check` is given.

    check(actions (T, 9)) -> a `PathCheck` (grits_lab.sim.env.ScoopEnv.check_path): per action,
    whether the arm cannot reach it and how fast it moves its joints. With `settings.slow_to_limits`
    each option is first slowed (`slow_to_limits`) until no action moves a joint faster than the
    Panda's velocity limit; it passes when that succeeds and no action after the first is
    unreachable (the first goes from where the scoop left the arm to the measured spoon pose: what
    the arm touches or misses there is the scoop's doing, not the plan's). Without it, an option
    passes when no action steps a joint more than `settings.max_joint_step` rad. The first option (`transfer_options`) that passes is taken; a lift
    that fails while rising skips its other pours. After `settings.max_checks` options without a
    pass, the one with the smallest joint step, then the fewest unreachable actions, is taken,
    with `reachable` False.

    heading_free (with `check`): when no option passes, the heading-free options
    (`transfer_options(settings, heading_free=True)`, their lifts from this callable, see
    `option_motion`) are tried in the same way, with `settings.max_checks` checks of their own. A
    heading-free lift the arm did not reach, or whose carry would cross an obstacle, fails without a
    check; each lift is solved once for all its pours. Every motion an option with the scoop's
    heading passes is therefore chosen as without them.
    """
    best: tuple[tuple[float, int], TransferPlan] | None = None
    n_checks = 0
    families = [transfer_options(settings)]
    if heading_free is not None and check is not None:
        families.append(transfer_options(settings, heading_free=True))
        lifted: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}  # one heading-free lift per planned lift, whatever the pour

        def heading_free_once(lift: np.ndarray, solve: HeadingFreeLift = heading_free) -> tuple[np.ndarray, np.ndarray]:
            key = np.ascontiguousarray(lift).tobytes()
            if key not in lifted:
                lifted[key] = solve(lift)
            return lifted[key]

        heading_free = heading_free_once
    for options in families:
        failed_lift, family_checks = None, 0
        for option in options:
            if failed_lift == (option.level_steps, option.level_yaw_deg):
                continue
            try:
                actions, stages, lift_reached = option_motion(current, target, obstacles, settings, max_step, spoon_reach,
                                                              target_heading, option, pour_edge, heading_free)
            except InputError:
                if not option.heading_free:
                    raise
                continue  # a carry from where this lift ends would cross an obstacle: the option fails
            if check is None:
                return TransferPlan(actions, stages, option, reachable=True, n_checks=0)
            if not lift_reached:  # the arm cannot lift with its heading free: no motion to check
                failed_lift = (option.level_steps, option.level_yaw_deg)
                continue
            n_checks += 1
            family_checks += 1
            if settings.slow_to_limits:
                actions, stages, answer, within = slow_to_limits(current, actions, stages, check, settings.max_slowdown)
                bad = answer.speed_ratios > 1.0 + 1e-9 if not within else np.zeros(len(actions), dtype=bool)
                key_step = float(answer.speed_ratios.max())
            else:
                answer = check(actions)
                bad = answer.joint_steps > settings.max_joint_step
                key_step = max(float(answer.joint_steps.max()), settings.max_joint_step)
            unreachable = answer.unreachable.copy()
            if settings.avoid_arm_contact and answer.touches is not None:  # an arm that would strike the table or a bowl
                unreachable |= answer.touches
            unreachable[0] = False  # where the scoop left the arm (see above)
            bad = bad | unreachable
            plan = TransferPlan(actions, stages, option, not bad.any(), n_checks)
            if plan.reachable:
                return plan
            key = (key_step, int(answer.unreachable[1:].sum()))
            if best is None or key < best[0]:
                best = (key, plan)
            if stages[int(np.argmax(bad))] == "lift":
                failed_lift = (option.level_steps, option.level_yaw_deg)
            if family_checks >= settings.max_checks:
                break
    assert best is not None, "no option could be checked"
    best[1].n_checks = n_checks
    return best[1]


def lift_length(path: np.ndarray) -> int:
    """Actions at the start of `path` that rise straight up from where the spoon was."""
    xy = path[0, :2]
    n = 0
    for pose in path:
        if np.linalg.norm(pose[:2] - xy) > 1e-6:
            break
        n += 1
    return n
