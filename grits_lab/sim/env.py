"""`ScoopEnv`: the scooping world behind the Gymnasium contract (reset / step / close).

The action is a 9-D spoon pose target (xyz in metres + 6-D rotation, world frame, the spoon tool
frame of `shapes.py`) at `SimConfig.control_hz` (10 Hz). Underneath, the pose path from the
previous target to the new one is cut into `ik_per_action` pieces, each solved by IK and tracked
by joint position control for its share of the physics steps (more when its joints would move
faster than the Panda's limits: `SimConfig.joint_speed_cap`). Every reset builds a fresh world
(new PyBullet client state), samples the food's particles from the env's seeded generator and
lets them settle, so the same seed and actions always give the same episode.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Iterator

import numpy as np

from grits_lab.errors import InputError
from grits_lab.geometry import cubic_pose_path, matrix_to_rot6d, rot6d_to_matrix
from grits_lab.seeding import derive_seed, make_rng
from grits_lab.sim.cameras import CameraImage, render
from grits_lab.sim.sim_config import MAX_SOLVER_ITERATIONS, SimConfig, steps_per_action, time_step_expectation
from grits_lab.sim.foods import FoodSpec, level_count, load_foods, sample_particles
from grits_lab.sim.spill_metrics import COVERAGE_THRESHOLD, SpillTracker, above_spoon_rim, classify, fill_height, spoon_coverage
from grits_lab.sim.robot import COARSE_IK, FINE_IK, HEADING_FREE_TOLERANCE, LIMIT_AVOID_STEP, REST_POSE, IKConvergence, PandaKinematics, joint_speed_ratio, pose_to_matrix, slowed_steps, spoon_in_hand
from grits_lab.sim.shapes import TARGET_BOWL, BowlGeometry, SpoonGeometry
from grits_lab.sim.world import CONSTRAINT_ERP, TABLE_TOP, World, build_static_scene, build_world, settle

DEFAULT_FOOD = "mung_beans"
# Metres the arm's links keep from the table and the bowls on a checked path (`check_path`): a
# planned motion that brings the arm closer touches them once it lags its command.
ARM_CLEARANCE = 0.005


@dataclass(frozen=True)
class PathCheck:
    """`ScoopEnv.check_path`'s answer, one entry per action checked: unreachable (T,) (an IK
    residual over the tolerance on the way), joint_steps (T,) (the largest change of a commanded
    joint over the action, rad), and the joint target after the last action solved (7,). A check
    that stopped at an unreachable action (`stop_at_unreachable`) reports every action after it
    unreachable, with joint step and speed ratio 0 and not touching."""

    unreachable: np.ndarray
    joint_steps: np.ndarray
    joints: np.ndarray
    speed_ratios: np.ndarray  # (T,) the largest joint step over that joint's Panda limit per action (> 1: too fast)
    # (T,) the arm (not the spoon) within ARM_CLEARANCE of the table or a bowl at the action's end;
    # None when the check was not asked for it
    touches: np.ndarray | None = None

    def folded(self, n: int) -> "PathCheck":
        """The check of the first `n` actions, what the later ones found folded into the n-th: it is
        unreachable, touches or moves as fast as the fastest of them. For a motion checked with the
        actions that follow it (a hold after a pour, which shapes the spline's last span)."""
        if n >= len(self.unreachable):
            return self
        tail = slice(n - 1, None)
        unreachable, steps, ratios = self.unreachable[:n].copy(), self.joint_steps[:n].copy(), self.speed_ratios[:n].copy()
        unreachable[-1], steps[-1], ratios[-1] = self.unreachable[tail].any(), self.joint_steps[tail].max(), self.speed_ratios[tail].max()
        touches = None
        if self.touches is not None:
            touches = self.touches[:n].copy()
            touches[-1] = self.touches[tail].any()
        return PathCheck(unreachable, steps, self.joints, ratios, touches)

    @property
    def n_checked(self) -> int:
        return int(len(self.unreachable))

    @property
    def n_unreachable(self) -> int:
        return int(np.sum(self.unreachable))

    @property
    def max_joint_step(self) -> float:
        return float(np.max(self.joint_steps, initial=0.0))


def pose9_to_matrix(pose9: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rot6d_to_matrix(np.asarray(pose9[3:9], dtype=np.float64))
    m[:3, 3] = pose9[:3]
    return m


def matrix_to_pose9(m: np.ndarray) -> np.ndarray:
    return np.concatenate([m[:3, 3], matrix_to_rot6d(m[:3, :3])])


def interpolate_pose(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    """Pose between (4, 4) poses a and b: linear in position, geodesic (slerp) in rotation."""
    rel = a[:3, :3].T @ b[:3, :3]
    angle = math.acos(np.clip((np.trace(rel) - 1) / 2, -1.0, 1.0))
    out = np.eye(4)
    out[:3, 3] = (1 - t) * a[:3, 3] + t * b[:3, 3]
    if angle < 1e-9:
        out[:3, :3] = b[:3, :3] if t >= 1 else a[:3, :3]
        return out
    axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    if np.linalg.norm(axis) < 1e-9:  # 180 degrees: any perpendicular axis
        w, v = np.linalg.eigh(rel + rel.T)
        axis = v[:, -1]
    axis = axis / np.linalg.norm(axis)
    th = t * angle
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    out[:3, :3] = a[:3, :3] @ (np.eye(3) + math.sin(th) * k + (1 - math.cos(th)) * k @ k)
    return out


@dataclass
class SceneGeometry:
    """What an episode's layout looks like; all positions world frame, metres."""

    source_bowl_center: list[float]  # bowl frame origin: centre of its bottom, on the table
    source_bowl_radius: float  # inner radius at the rim
    source_bowl_floor_radius: float
    source_bowl_floor_height: float  # world z of the inner floor
    source_bowl_rim_height: float  # world z of the rim
    target_bowl_position: list[float]
    target_bowl_orientation: list[float]  # quaternion xyzw
    target_bowl_radius: float
    target_bowl_rim_height: float
    spoon: dict[str, float]
    spoon_home: list[float]  # 9-D
    cameras: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def scene_geometry(config: SimConfig, target_xy: np.ndarray, source: BowlGeometry = BowlGeometry(),
                   target: BowlGeometry = TARGET_BOWL, spoon: SpoonGeometry = SpoonGeometry()) -> SceneGeometry:
    from grits_lab.sim.cameras import camera_to_world, intrinsics

    sx, sy = config.source_bowl_xy
    home = pose_to_matrix(np.array(config.spoon_home[:3]), np.array(config.spoon_home[3:]))
    return SceneGeometry(
        source_bowl_center=[sx, sy, 0.0],
        source_bowl_radius=source.rim_radius,
        source_bowl_floor_radius=source.floor_radius,
        source_bowl_floor_height=source.floor_thickness,
        source_bowl_rim_height=source.depth,
        target_bowl_position=[float(target_xy[0]), float(target_xy[1]), 0.0],
        target_bowl_orientation=[0.0, 0.0, 0.0, 1.0],
        target_bowl_radius=target.rim_radius,
        target_bowl_rim_height=target.depth,
        spoon={"bowl_length": 2 * spoon.half_length, "bowl_width": 2 * spoon.half_width, "rim_height": spoon.rim_height,
               "handle_length": spoon.handle_length, "handle_elevation_deg": spoon.handle_elevation_deg,
               "bowl_area": spoon.bowl_area},
        spoon_home=matrix_to_pose9(home).tolist(),
        cameras=[{"name": c.name, "width": c.width, "height": c.height, "intrinsics": intrinsics(c).tolist(),
                  "camera_to_world": camera_to_world(c).tolist()} for c in config.cameras],
    )


class ScoopEnv:
    """The simulated scooping task; see the module docstring. Not thread-safe; one per process/actor."""

    def __init__(self, config: SimConfig | None = None) -> None:
        self.config = config or SimConfig()
        self.foods = load_foods(self.config.foods_file)
        self.kinematics = PandaKinematics()
        self.world: World | None = None
        self.spoon_geometry = SpoonGeometry()
        self._hand_in_spoon = spoon_in_hand(self.spoon_geometry)
        self._spoon_in_grasp = np.linalg.inv(self._hand_in_spoon)
        self._home_joints: np.ndarray | None = None
        self._seed_stream: np.random.Generator | None = None

    # ---- Gymnasium contract ------------------------------------------------------------------
    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Build and settle a new world.

        options: `food` (name, default mung_beans), `level` (default the food's first level),
        `food_spec` (a FoodSpec used instead of the library, e.g. `foods.primitive_food`),
        `n_particles` (overrides the level's count), `target_xy` (target bowl centre).
        `seed=None` continues the env's own seed stream (seeded by the last explicit seed; OS
        entropy only before the first one), as Gymnasium's contract asks.
        """
        options = dict(options or {})
        unknown = set(options) - {"food", "level", "food_spec", "n_particles", "target_xy"}
        if unknown:
            raise InputError(f"unknown reset option {sorted(unknown)[0]!r}; valid: food, level, food_spec, n_particles, target_xy")
        if seed is None:
            if self._seed_stream is None:
                self._seed_stream = np.random.default_rng()
            seed = int(self._seed_stream.integers(2**31))
        else:
            self._seed_stream = make_rng(derive_seed(int(seed), "next_episode"))
        self.seed = int(seed)
        rng = make_rng(self.seed)
        spec: FoodSpec | None = options.get("food_spec")
        name = options.get("food", DEFAULT_FOOD if spec is None else "custom")
        if spec is None:
            spec = self.foods.get(name)
        level = options.get("level", next(iter(spec.levels)))
        count = int(options["n_particles"]) if options.get("n_particles") is not None else level_count(spec, name, level)
        if count < 0:
            raise InputError(f"n_particles must be >= 0, got {count}")
        self.food_name, self.food, self.level = name, spec, level
        components = sample_particles(spec, count, rng) if count else []
        self.close_world()
        joints = self._home()
        target_xy = options.get("target_xy")
        if target_xy is None:  # its own stream, so the layout of a seed does not depend on the food
            layout = make_rng(derive_seed(self.seed, "target_bowl"))
            (cx, cy), (sx, sy) = self.config.target_workspace_center, self.config.target_workspace_size
            target_xy = (cx + layout.uniform(-sx / 2, sx / 2), cy + layout.uniform(-sy / 2, sy / 2))
        self.world = build_world(self.config, components, rng, target_xy=tuple(target_xy), joints=joints)
        table, source_bowl, target_bowl = build_static_scene(self.kinematics.client, self.world.source_bowl_position,
                                                             self.world.target_bowl_position)
        self.kinematics.set_obstacles(table, source_bowl + target_bowl)
        self.world.command_joints(joints)
        self._joint_target = joints.copy()
        self._pose_target = self.world.spoon_matrix()
        settle(self.world)
        self.tracker = SpillTracker(len(self.world.particles))
        self.step_count = 0
        self.ik_failures = 0
        self.max_joint_speed_ratio = 0.0
        self.slowed_actions = 0
        self.action_time_s = 0.0
        self.arm_contact_steps = 0
        self.carry_peak_spoon_accel = 0.0
        self._spoon_velocity: np.ndarray | None = None
        self._solver_ramp: list[int] = []  # iterations of the next physics steps (`set_solver_iterations`)
        self._erp_ramp: list[float] = []  # constraint error reduction of the next physics steps (`set_time_step`)
        self.rest_pull = True
        self.ik_refine = False
        counts = self._classify()
        self._refuse_unsettled(counts.outside_source)
        self.tracker.observe(counts)
        self.initial_outside = int(counts.outside_source.sum())
        return self._obs(), self._info(ik_failure=False)

    def _refuse_unsettled(self, outside: np.ndarray) -> None:
        """InputError when particles came to rest outside the source bowl before any action: a food
        that does not fit the bowl, whose losses would otherwise be scored as the policy's spill."""
        if not outside.any():
            return
        w = self._require_world()
        below = int((w.particle_positions()[outside, 2] < -0.01).sum())
        raise InputError(
            f"food {self.food_name!r} (level {self.level!r}, seed {self.seed}): {int(outside.sum())} of {len(outside)} particles "
            f"came to rest outside the source bowl after settling ({below} below the table), before any action; "
            "the food does not fit the bowl: use fewer or smaller particles")

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Move the spoon towards the 9-D pose `action` for one control period (1 / control_hz s), or
        for longer when its joints would exceed `SimConfig.joint_speed_cap` x the Panda's limits
        (info["slowdown"]: control periods taken), along the straight pose path from the last
        action (`SimConfig.ik_per_action` IK pieces). InputError for a non-finite or mis-shaped action."""
        world = self._require_world()
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (9,) or not np.all(np.isfinite(a)):
            raise InputError(f"action must be a finite 9-vector (xyz + 6-D rotation), got shape {a.shape}")
        target = pose9_to_matrix(a)
        return self._move(world, target, self._straight_pieces(self._pose_target, target))

    def _straight_pieces(self, start: np.ndarray, target: np.ndarray) -> list[np.ndarray]:
        """The `SimConfig.ik_per_action` (4, 4) poses that cut the straight pose path from `start` to `target`."""
        n = self.config.ik_per_action
        return [interpolate_pose(start, target, (k + 1) / n) for k in range(n)]

    def step_along(self, poses: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """`step` to the last of the 9-D poses `poses` (n, 9) through the others: one IK piece per
        pose, the control period's physics steps shared among them (n <= `ScoopEnv.substeps`).
        A motion generator's finer path between two actions (`geometry.cubic_pose_path`); the
        records and info are `step`'s. InputError for other shapes or non-finite poses."""
        world = self._require_world()
        p = np.asarray(poses, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 9 or not 1 <= len(p) <= self.substeps or not np.all(np.isfinite(p)):
            raise InputError(f"poses must be finite, (n, 9) with 1 <= n <= {self.substeps}; got shape {p.shape}")
        poses = [pose9_to_matrix(x) for x in p]
        return self._move(world, poses[-1], poses, converged=FINE_IK)

    def _move(self, world: World, target: np.ndarray, poses: list[np.ndarray], converged: IKConvergence = COARSE_IK
              ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """One action to the (4, 4) spoon pose `target` through the IK pieces `poses` (`step`),
        each solved to the residual `converged` (`PandaKinematics.solve`)."""
        start = self._pose_target
        cfg = self.config
        if cfg.freeze_distance is not None and len(world.particles):
            world.freeze(self._far_at_rest(world, start[:3, 3], target[:3, 3], cfg.freeze_distance))
        pieces = len(poses)
        steps = self.substeps
        joints_before = self._joint_target.copy()
        failed = False
        done = executed = 0
        for k, joints, reached in self._track(poses, self._joint_target, converged=converged):
            failed |= not reached
            n = (steps * (k + 1)) // pieces - done
            done += n
            n_run = slowed_steps(joints - self._joint_target, n, world.time_step, cfg.joint_speed_cap)
            self._follow(world, self._joint_target, joints, n_run)
            self._joint_target = joints
            executed += n_run
        self._pose_target = target
        self.step_count += 1
        self.ik_failures += int(failed)
        self.slowed_actions += int(executed > steps)
        self.action_time_s += executed * world.time_step
        delta = self._joint_target - joints_before
        joint_step = float(np.abs(delta).max())
        speed_ratio = joint_speed_ratio(delta, cfg.control_hz)
        executed_ratio = speed_ratio * steps / executed  # the speed the arm was commanded at, on average over the action
        self.max_joint_speed_ratio = max(self.max_joint_speed_ratio, speed_ratio)
        self.arm_contact_steps += int(world.arm_touches_static())
        before = self.tracker.history[-1] if self.tracker.history else 0
        spilled = self.tracker.update(self._classify(), thrown=executed_ratio > 1.0 + 1e-6)
        truncated = self.step_count >= cfg.max_episode_steps
        return self._obs(), -float(spilled - before), False, truncated, self._info(
            ik_failure=failed, joint_step=joint_step, joint_speed_ratio=speed_ratio, slowdown=executed / steps)

    def _follow(self, world: World, previous: np.ndarray, joints: np.ndarray, n: int) -> None:
        """Move the arm's joint targets from `previous` to `joints` (7,) over `n` physics steps, as
        `SimConfig.joint_command` says."""
        if n <= 0:
            return
        if self.config.joint_command == "stepwise":
            world.command_joints(joints)
            for _ in range(n):
                self._physics_step(world)
            return
        velocity = (joints - previous) / (n * world.time_step)
        for i in range(1, n + 1):
            world.command_joints(previous + (joints - previous) * (i / n), velocity)
            self._physics_step(world)

    def _physics_step(self, world: World) -> None:
        """One physics step; in the lift and carry (from the step that leaves the scoop), the spoon's
        acceleration from its velocity change over the step goes into `carry_peak_spoon_accel` (m/s^2)."""
        if self._solver_ramp:
            world.client.setPhysicsEngineParameter(numSolverIterations=self._solver_ramp.pop(0))
        if self._erp_ramp:
            world.client.setPhysicsEngineParameter(erp=self._erp_ramp.pop(0))
        world.step(1)
        if self._spoon_velocity is None:  # outside the lift and carry (`set_stage`)
            return
        v = np.asarray(world.client.getBaseVelocity(world.spoon)[0], dtype=np.float64)
        accel = float(np.linalg.norm(v - self._spoon_velocity)) / world.time_step
        self.carry_peak_spoon_accel = max(self.carry_peak_spoon_accel, accel)
        self._spoon_velocity = v

    def set_stage(self, stage: str, rest_pull: bool | None = None, ik_refine: bool | None = None) -> None:
        """Name the task stage the next actions belong to (scoop, lift, carry, pour, after_pour): every
        particle spilled from then on is attributed to it (`metrics()["spill_attribution"]`). A reset
        starts in "scoop". rest_pull: whether the IK pulls the arm towards its rest posture from now
        on (`PandaKinematics.solve`); None: only in the scoop. ik_refine: whether an IK solve that
        stops short of its residual is refined by damped least squares from where the arm is
        (`PandaKinematics.solve`); None: in every stage but the scoop. ValueError for another stage name."""
        world = self._require_world()
        self.tracker.set_stage(stage)
        # The lift and carry measure the spoon's acceleration (`_physics_step`) from its velocity now.
        self._spoon_velocity = (np.asarray(world.client.getBaseVelocity(world.spoon)[0], dtype=np.float64)
                                if stage in ("lift", "carry") else None)
        self.rest_pull = stage == "scoop" if rest_pull is None else bool(rest_pull)
        self.ik_refine = stage != "scoop" if ik_refine is None else bool(ik_refine)

    @property
    def pose_target(self) -> np.ndarray:
        """(4, 4) the spoon pose the last action asked for (world frame, m): where the next one starts."""
        self._require_world()
        return self._pose_target.copy()

    def anchor_pose_target(self) -> None:
        """Make the next action start from the spoon pose the arm's joint target reaches (forward
        kinematics on the kinematic copy) instead of the pose last asked for. They differ when the
        last action was out of reach: the arm kept its last reachable target (an IK failure) while
        the pose asked for lay elsewhere, and the next action's path would start from there. The
        stages after the scoop start with it (`run_transfer`). RuntimeError before `reset`."""
        self._require_world()
        self._pose_target = self._spoon_pose_at(self._joint_target)

    @property
    def substeps(self) -> int:
        """Physics steps per action at the current time step (`set_time_step`; a reset starts at
        `SimConfig.substeps`)."""
        return steps_per_action(self.config.control_hz, self._require_world().time_step)

    def set_time_step(self, time_step: float | None) -> None:
        """The physics time step from now on, seconds (PyBullet's fixedTimeStep); None:
        `SimConfig.time_step`. Every reset starts again at the config's. The stages after the
        scoop halve it (`TransferSettings.time_step`): a heap carried at 1/120 s creeps off the
        spoon, at 1/240 s it stays (docs/archive/oracle_high_physics_fine). An action keeps its
        control period (`SimConfig.control_hz`), run over `substeps` steps; the arm's motors keep their
        gain per second (`robot.ARM_POSITION_GAIN_PER_S`).

        The spoon hangs from the hand by a fixed constraint that Bullet holds like a spring whose
        stiffness per second is erp / time_step^2 (`world.CONSTRAINT_ERP`). Switched with erp kept, a
        halved step makes it four times as stiff in one step and the held spoon jolts (an empty
        spoon held still: 3.9 m/s^2 in the first step, then a swing); so the step starts at erp x
        (new / old)^2, the old stiffness, and erp returns to `CONSTRAINT_ERP` in equal steps over the
        next action (0.2 m/s^2). InputError for a step outside [0.0001, 0.02] s, one whose control
        period is not a whole number of steps, or one with fewer steps per action than
        `SimConfig.ik_per_action`; RuntimeError before `reset`."""
        world = self._require_world()
        dt = self.config.time_step if time_step is None else float(time_step)
        expectation = time_step_expectation(dt, self.config.control_hz, self.config.ik_per_action)
        if expectation:
            raise InputError(f"time step must be {expectation}, got {dt}")
        ratio = dt / world.time_step
        world.client.setPhysicsEngineParameter(fixedTimeStep=dt)
        world.time_step = dt
        if ratio == 1.0:
            return
        start, n = CONSTRAINT_ERP * ratio ** 2, self.substeps
        self._erp_ramp = [start + (CONSTRAINT_ERP - start) * (k + 1) / n for k in range(n)]
        world.client.setPhysicsEngineParameter(erp=start)

    def set_solver_iterations(self, iterations: int | None, ramp_steps: int = 0) -> None:
        """Constraint-solver iterations per physics step from now on (PyBullet's
        numSolverIterations); None: `SimConfig.solver_iterations`. Every reset starts again at
        the config's. The stages after the scoop raise it (`TransferSettings.solver_iterations`).
        ramp_steps: reach it in equal steps over the next `ramp_steps` physics steps instead of at
        once. The loaded spoon hangs from the arm's motors through a constraint chain that 30
        iterations leave slack and 100 pull tight: switched in one step the spoon jolts (3.7 m/s^2,
        then a 1.3 cm/s swing; rule-based, fudge, high, trial 0), ramped over one action it does
        not (0.5 m/s^2). InputError outside [1, MAX_SOLVER_ITERATIONS]; RuntimeError before `reset`."""
        world = self._require_world()
        n = self.config.solver_iterations if iterations is None else int(iterations)
        if not 1 <= n <= MAX_SOLVER_ITERATIONS:
            raise InputError(f"solver iterations must be in [1, {MAX_SOLVER_ITERATIONS}], got {n}")
        now = int(world.client.getPhysicsEngineParameters()["numSolverIterations"])
        self._solver_ramp = [int(round(now + (n - now) * (k + 1) / ramp_steps)) for k in range(ramp_steps)] if ramp_steps > 0 else []
        if not self._solver_ramp:
            world.client.setPhysicsEngineParameter(numSolverIterations=n)

    def _track(self, poses: list[np.ndarray], joints: np.ndarray, rest_pull: bool | None = None,
               converged: IKConvergence = COARSE_IK, ik_refine: bool | None = None) -> Iterator[tuple[int, np.ndarray, bool]]:
        """The joint targets of one action: for each of its pieces, the (4, 4) spoon poses `poses`,
        (piece index, joint target (7,), whether IK reached the piece). An unreachable piece keeps
        the last reachable joint target. rest_pull: the IK's null-space pull towards the rest
        posture (`PandaKinematics.solve`); None: as `set_stage` set it, on in the scoop (the
        policies' and demonstrations' arm) and off in the scripted stages after it. converged: the
        IK's stopping residual, ik_refine its damped least-squares refinement (`PandaKinematics.solve`;
        None: as `set_stage` set it)."""
        cfg = self.config
        if rest_pull is None:
            rest_pull = self.rest_pull
        if ik_refine is None:
            ik_refine = self.ik_refine
        for k, pose in enumerate(poses):
            ik = self.kinematics.solve(pose @ self._hand_in_spoon, joints, cfg.ik_position_tolerance, cfg.ik_orientation_tolerance,
                                       rest_pull=rest_pull, converged=converged, refine=ik_refine)
            if ik.ok:
                joints = ik.joints
            yield k, joints, ik.ok

    def check_path(self, path: np.ndarray, rest_pull: bool | None = None, touches: bool = False,
                   ik_refine: bool | None = None, stop_at_unreachable: bool = False,
                   interpolation: str = "linear") -> PathCheck:
        """What the arm would do with the actions `path` (T, 9) from its present joint target, on the
        kinematic copy only (the world is not touched): the same IK tracking as `step` (with
        `rest_pull` and `ik_refine` as `_track`: None the current stage's; pass the settings of the
        stages after the scoop for a motion of theirs), so entry t is what `step(path[t])` would
        report as `ik_failure`, `joint_step` and `joint_speed_ratio`. With `touches`, also whether the arm comes within
        ARM_CLEARANCE of the table or a bowl (`PathCheck.touches`; None without). With
        `stop_at_unreachable`, once an action after the first is unreachable the rest are reported
        unreachable (joint step 0) without solving them: enough to fail a path, and a path the
        arm cannot follow no longer costs a full IK refinement (`PandaKinematics.refine`) at every
        piece after it. interpolation: "linear", the pieces `step` solves (straight,
        `SimConfig.ik_per_action` an action, to COARSE_IK); "cubic", those `step_along` solves for a
        motion along `geometry.cubic_pose_path` through `path` from the pose last asked for
        (`SimConfig.substeps` an action, to FINE_IK, whatever `set_time_step` set), as the stages after the scoop move with `transfer.interpolation:
        cubic`: the check then solves the very IK the motion will. Raises RuntimeError before
        `reset`; InputError for another interpolation.
        """
        self._require_world()
        if interpolation not in ("linear", "cubic"):
            raise InputError(f"interpolation must be linear or cubic, got {interpolation!r}")
        joints, start = self._joint_target.copy(), self._pose_target
        unreachable, steps, ratios, touching = [], [], [], []
        actions = np.asarray(path, dtype=np.float64).reshape(-1, 9)
        spline = cubic_pose_path(matrix_to_pose9(start), actions, self.config.substeps) if interpolation == "cubic" else None
        for i, action in enumerate(actions):
            if stop_at_unreachable and i > 1 and unreachable[-1]:
                rest = len(actions) - i
                unreachable += [True] * rest
                steps += [0.0] * rest
                ratios += [0.0] * rest
                touching += [False] * rest if touches else []
                break
            target = pose9_to_matrix(action)
            before, failed = joints, False
            if spline is None:
                pieces, converged = self._straight_pieces(start, target), COARSE_IK
            else:
                pieces, converged = [pose9_to_matrix(x) for x in spline[i]], FINE_IK
            for _, joints, reached in self._track(pieces, joints, rest_pull, converged=converged, ik_refine=ik_refine):
                failed |= not reached
            start = target
            unreachable.append(failed)
            steps.append(float(np.abs(joints - before).max()))
            ratios.append(joint_speed_ratio(joints - before, self.config.control_hz))
            if touches:
                touching.append(self.kinematics.touches_obstacles(joints, ARM_CLEARANCE))
        return PathCheck(np.array(unreachable, dtype=bool), np.array(steps), joints, np.array(ratios),
                         np.array(touching, dtype=bool) if touches else None)

    def heading_free_path(self, path: np.ndarray, limit_step: float = LIMIT_AVOID_STEP) -> tuple[np.ndarray, np.ndarray]:
        """The spoon poses (T, 9) the arm reaches when it follows the actions `path` (T, 9) from its
        present joint target holding each one's spoon centre and tilt but not its heading about the
        world's vertical, its joints stepping away from their limits in the larger null space that
        leaves (`PandaKinematics.solve_heading_free`, at most `limit_step` rad per action), on the
        kinematic copy only; and (T,) whether each was reached: its centre within 1 mm and its tilt
        within 0.01 rad (`HEADING_FREE_TOLERANCE`; the lift's actions are the poses reached, so a
        looser answer would tip the loaded spoon by its miss, and the level carry after it would
        turn it back in one action). A spoon turned
        about the vertical through its centre keeps its load where it is, so the poses are a motion
        of the same spoon with its wrist unwound. RuntimeError before `reset`."""
        self._require_world()
        pivot = self._spoon_in_grasp[:3, 3]
        joints, poses, reached = self._joint_target.copy(), [], []
        for action in np.asarray(path, dtype=np.float64).reshape(-1, 9):
            joints, residual = self.kinematics.solve_heading_free(pose9_to_matrix(action) @ self._hand_in_spoon, joints, pivot,
                                                                  limit_step=limit_step)
            poses.append(matrix_to_pose9(self._spoon_pose_at(joints)))
            reached.append(HEADING_FREE_TOLERANCE.reached(float(np.linalg.norm(residual[:3])), float(np.linalg.norm(residual[3:]))))
        return np.array(poses, dtype=np.float32), np.array(reached, dtype=bool)

    @staticmethod
    def _far_at_rest(world: World, a: np.ndarray, b: np.ndarray, distance: float) -> np.ndarray:
        """(N,) particles farther than `distance` from the segment a-b (the spoon's path) and at rest (or frozen)."""
        pos = world.particle_positions()
        seg = b - a
        t = np.clip((pos - a) @ seg / max(float(seg @ seg), 1e-12), 0.0, 1.0)
        far = np.linalg.norm(pos - (a + t[:, None] * seg), axis=1) > distance
        return far & (world.frozen | (world.particle_speeds() < 0.01))

    def close(self) -> None:
        self.close_world()
        self.kinematics.close()

    # ---- queries -----------------------------------------------------------------------------
    def spoon_pose(self) -> np.ndarray:
        """(4, 4) measured pose of the spoon frame (world); place the spoon mesh's points with it."""
        return self._require_world().spoon_matrix()

    def source_bowl_pose(self) -> np.ndarray:
        """(4, 4) pose of the source bowl frame (world); the bowl mesh is in this frame."""
        m = np.eye(4)
        m[:3, 3] = self._require_world().source_bowl_position
        return m

    def target_bowl_pose(self) -> np.ndarray:
        m = np.eye(4)
        m[:3, 3] = self._require_world().target_bowl_position
        return m

    def particle_positions(self) -> np.ndarray:
        """(N, 3) particle centres, world frame."""
        return self._require_world().particle_positions()

    def particle_parameters(self) -> list[dict[str, Any]]:
        """Per-component particle parameters of this episode (shape, size, count, mean dynamics)."""
        return [p.describe() for p in self._require_world().particle_components]

    def segmentation_ids(self) -> dict[str, list[int]]:
        """Body ids seen in segmentation masks, by name: food, spoon, source_bowl, target_bowl, robot, table."""
        w = self._require_world()
        return {
            "food": [int(b) for b in w.particles],
            "spoon": [w.spoon],
            "source_bowl": list(w.source_bowl),
            "target_bowl": list(w.target_bowl),
            "robot": [w.robot],
            "table": [w.table],
        }

    def render_cameras(self) -> dict[str, CameraImage]:
        """Render every configured camera now (slow: tens of ms per camera): name -> CameraImage."""
        w = self._require_world()
        return {cam.name: render(w.client, cam) for cam in self.config.cameras}

    def scene(self) -> SceneGeometry:
        return scene_geometry(self.config, self._require_world().target_bowl_position)

    def fill_height(self) -> float:
        """Food height in the source bowl now (m): 90th percentile of particle tops above the inner floor."""
        w = self._require_world()
        tops = np.array([p.radius for p in w.particle_components])[w.particle_component_index] if len(w.particles) else np.zeros(0)
        return fill_height(w.particle_positions(), tops, w.source_bowl_position, w.source_geometry)

    def spill_steps(self) -> np.ndarray:
        """(K,) int32: for each particle spilled now, the action step since `reset` at which it was
        last counted spilled (`SpillTracker.spill_steps`); the horizon label's input."""
        self._require_world()
        return self.tracker.spill_steps(self._classify())

    def metrics(self) -> dict[str, Any]:
        """Scoop metrics of the current state (counts of particles; see grits_lab.sim.spill_metrics)."""
        w = self._require_world()
        positions = w.particle_positions()
        counts = self._classify(positions)
        spoon = w.spoon_matrix()
        coverage = spoon_coverage(positions[counts.lifted], w.particle_radii()[counts.lifted], spoon, self.spoon_geometry)
        scooped = int(counts.lifted.sum())
        success = scooped >= 1 if self.food.success_rule == "items" else coverage >= COVERAGE_THRESHOLD
        spilled = self.tracker.current(counts)
        return {
            "n_particles": int(len(w.particles)),
            "spilled": spilled,
            "scooped": scooped,
            "in_spoon": int(counts.in_spoon.sum()),
            "transferred": int((counts.in_target & ~counts.in_spoon).sum()),
            "spoon_coverage": coverage,
            "scoop_success": bool(success),
            "scoop_failure": not success,
            "spillage": spilled > 0,
            "first_spill_step": self.tracker.first_spill_step,
            "spill_attribution": self.tracker.attribution(counts),
            "above_spoon_rim": int((counts.lifted & above_spoon_rim(positions, spoon, self.spoon_geometry)).sum()),
            # particles whose centre lies below the table's top: passed through a bowl's floor or the
            # table, which no real food does (a simulation fault; outside a bowl they count as spilled)
            "sunk_below_table": int((positions[:, 2] < TABLE_TOP).sum()),
            "ik_failures": self.ik_failures,
            "max_joint_speed_ratio": self.max_joint_speed_ratio,  # the largest an action asked for (see _info)
            "slowed_actions": self.slowed_actions,  # actions slowed to SimConfig.joint_speed_cap
            "action_time_s": self.action_time_s,  # simulated seconds the actions took since reset
            "arm_contact_steps": self.arm_contact_steps,  # actions that ended with the arm touching the table or a bowl
            # the spoon's largest acceleration in the lift and carry, m/s^2, measured from its
            # velocity at every physics step (what a heap on it feels; `_physics_step`)
            "carry_peak_spoon_accel_mps2": self.carry_peak_spoon_accel,
        }

    def particle_counts(self) -> Any:
        """Where every particle is now (`spill_metrics.ParticleCounts`: per-particle masks of the spoon,
        the bowls and what is lifted). RuntimeError before `reset`."""
        return self._classify()

    # ---- internals ---------------------------------------------------------------------------
    def _spoon_pose_at(self, joints: np.ndarray) -> np.ndarray:
        """(4, 4) the spoon pose the arm at joints (7,) holds (forward kinematics on the kinematic copy)."""
        return self.kinematics.forward(joints) @ self._spoon_in_grasp

    def _home(self) -> np.ndarray:
        if self._home_joints is None:
            home = pose_to_matrix(np.array(self.config.spoon_home[:3]), np.array(self.config.spoon_home[3:]))
            ik = self.kinematics.solve(home @ self._hand_in_spoon, np.array(REST_POSE), 0.005, 0.05)
            if not ik.ok:
                raise InputError(f"spoon_home {list(self.config.spoon_home)} is out of the robot's reach")
            self._home_joints = ik.joints
        return self._home_joints.copy()

    def _classify(self, positions: np.ndarray | None = None):
        """The particles' `ParticleCounts` now; `carried` is looked up (`World.carried_by_spoon`) when
        a particle not yet counted spilled lies outside the spoon and both bowls."""
        w = self._require_world()
        if positions is None:
            positions = w.particle_positions()
        counts = classify(positions, w.spoon_matrix(), w.source_bowl_position, w.target_bowl_position,
                          w.source_geometry, w.target_geometry, w.spoon_geometry)
        outside = counts.outside_source & ~counts.in_target
        if (outside & ~counts.in_spoon & ~self.tracker.spilled_flags).any():
            # chains run through every grain not lying in a bowl (the source's counts below its rim)
            counts.carried = w.carried_by_spoon(through=counts.in_spoon | ~(counts.in_source | counts.in_target))
        return counts

    def _obs(self) -> dict[str, np.ndarray]:
        w = self._require_world()
        return {"ee_pose": matrix_to_pose9(w.spoon_matrix()).astype(np.float32),
                "joint_pos": w.joint_positions().astype(np.float32)}

    def _info(self, ik_failure: bool, joint_step: float = 0.0, joint_speed_ratio: float = 0.0,
              slowdown: float = 1.0) -> dict[str, Any]:
        # joint_step: the largest change of any arm joint's commanded angle over the action (rad);
        # joint_speed_ratio: the largest over that joint's Panda limit (robot.PANDA_MAX_JOINT_VELOCITY
        # per action) as the action asked for it: above 1 no Panda could follow in one control
        # period, and far above it is the IK leaving for another arm posture (an elbow or wrist
        # flip); slowdown: how many control periods the action took (> 1 when slowed to
        # SimConfig.joint_speed_cap).
        return {"step": self.step_count, "spilled": self.tracker.history[-1] if self.tracker.history else 0,
                "ik_failure": ik_failure, "ik_failures": self.ik_failures, "joint_step": joint_step,
                "joint_speed_ratio": joint_speed_ratio, "slowdown": slowdown}

    def _require_world(self) -> World:
        if self.world is None:
            raise RuntimeError("call reset() before using the environment")
        return self.world

    def close_world(self) -> None:
        if self.world is not None:
            self.world.close()
            self.world = None



def worker_env(context: Any, config: SimConfig) -> ScoopEnv:
    """The ScoopEnv a runner worker keeps between episodes (`grits_lab.runners.WorkerContext.reusable`):
    built in the worker, never pickled, rebuilt only when `config` changes."""
    from grits_lab.config import config_fingerprint

    return context.reusable(config_fingerprint(config), lambda: ScoopEnv(config))
