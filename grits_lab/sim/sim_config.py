"""Typed configuration of the simulated scooping world (physics, scene layout, cameras, control)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from grits_lab.config import require


@dataclass
class CameraConfig:
    """A fixed pinhole RGB-D camera looking from `eye` at `target` (world frame, metres)."""

    name: str
    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov_deg: float = 50.0  # vertical field of view
    width: int = 320
    height: int = 240
    near: float = 0.05
    far: float = 2.5

    def __post_init__(self) -> None:
        require(0 < self.fov_deg < 170, "fov_deg", self.fov_deg, "in (0, 170)")
        require(self.width >= 8 and self.height >= 8, "width/height", (self.width, self.height), "at least 8 pixels")
        require(0 < self.near < self.far, "near/far", (self.near, self.far), "0 < near < far")


def _default_cameras() -> list[CameraConfig]:
    # One camera facing the robot across the table (both bowls in view), one close to the source
    # bowl from the side (the food in detail).
    return [
        CameraConfig(name="front", eye=(1.15, 0.08, 0.62), target=(0.52, 0.08, 0.0)),
        CameraConfig(name="side", eye=(0.62, -0.5, 0.42), target=(0.6, -0.1, 0.02), fov_deg=45.0),
    ]


MAX_SOLVER_ITERATIONS = 200  # the most constraint-solver iterations per physics step a config may ask for


def steps_per_action(control_hz: float, time_step: float) -> int:
    """Physics steps of `time_step` seconds in one action at `control_hz`."""
    return int(round(1.0 / (control_hz * time_step)))


def time_step_expectation(time_step: float, control_hz: float, ik_per_action: int) -> str | None:
    """None when an episode can step its physics at `time_step` seconds (`SimConfig.time_step`,
    `TransferSettings.time_step`, `ScoopEnv.set_time_step`); otherwise what the step must be: in
    [0.0001, 0.02] s, a whole number of steps per action at `control_hz`, at least `ik_per_action`
    of them so that every IK piece is tracked for one."""
    steps = 1.0 / (control_hz * time_step) if time_step > 0 else 0.0
    if not (1e-4 <= time_step <= 0.02 and abs(steps - round(steps)) < 1e-6 and round(steps) >= ik_per_action):
        return (f"in [0.0001, 0.02] s with a whole number of at least {ik_per_action} steps per "
                f"{1.0 / control_hz:g} s action")
    return None


@dataclass
class SimConfig:
    """Everything that shapes an episode besides the food and the seed.

    Physics: 120 Hz keeps the coarse-grained particles of `foods.yaml` (4.5 mm and up) stable
    (no explosions, no tunnelling through the 2 mm spoon) while a bowl filled 3 cm deep steps
    about as fast as real time on one core (measured lever by lever in `benchmarks/bench_sim.py`);
    the authors' code used 1/256 s, reachable through `time_step`. 30 solver iterations hold a
    pile of six or more layers up: with 10, the bottom particles of a 2.8 cm pile sink 2.5 mm
    (spheres) to 5 mm (cylinders) into the bowl's floor; with 30, 0.4 mm (spheres) and 1.3-3 mm
    (cylinders), for little extra cost because contact detection, not the solver, dominates a step.
    """

    time_step: float = 1.0 / 120.0
    solver_iterations: int = 30
    # Bullet keeps contact points up to this distance (default 2 cm). With millimetre particles the
    # default makes every particle track all neighbours within 2 cm; 1 mm keeps only touching
    # neighbours (see benchmarks/bench_sim.py for the measured effect).
    contact_breaking_threshold: float = 0.001
    # Freezing: before each action, particles at rest farther than this (metres) from the spoon's
    # path over the action are made static (mass 0) and the others dynamic again, so the solver
    # only works where the spoon is. None keeps every particle dynamic (the default; its effect on
    # speed and on spill counts is measured in benchmarks/bench_sim.py).
    freeze_distance: float | None = None
    control_hz: float = 10.0  # rate of the 9-D pose actions
    ik_per_action: int = 4  # IK solves per action on the interpolated pose path
    # How the arm's joint motors follow the IK solutions. "interpolated": at every physics step the
    # motors get the joint targets on the straight line between two solutions and that line's
    # velocity, as a robot's motion generator streams them (libfranka at 1 kHz); the spoon then
    # moves with the commanded path's own accelerations. "stepwise" (scoop-v4 and earlier): each
    # solution is held for its physics steps with a zero velocity target, so the arm lurches to each
    # one and stops; measured on the expert's carry (commanded peak 0.2 m/s^2), the spoon's
    # acceleration was 1.1 m/s^2 median and up to 9 m/s^2, which shook loose food off the spoon.
    joint_command: Literal["interpolated", "stepwise"] = "interpolated"
    # The fastest the arm's joints may be commanded, as a multiple of the Panda's joint velocity
    # limits (robot.PANDA_MAX_JOINT_VELOCITY). A piece of an action whose joint targets would need
    # more is slowed: it runs over as many more physics steps as its speed needs, so the action
    # takes longer than one control period, as a robot's motion generator time-scales a path it
    # cannot follow at the asked speed. None: every action runs in one control period whatever
    # speed it needs (scoop-v7 and earlier). With joint_command "stepwise" the cap only lengthens
    # how long each target is held; the motors then reach it as fast as their forces allow.
    joint_speed_cap: float | None = 1.0
    ik_position_tolerance: float = 0.01  # metres; larger IK residuals count as IK failures
    ik_orientation_tolerance: float = 0.15  # radians
    # Settling before an episode: run at least settle_min_s, stop when every particle is slower
    # than settle_speed (m/s), give up at settle_max_s.
    settle_min_s: float = 0.4
    settle_max_s: float = 1.5
    settle_speed: float = 0.03
    source_bowl_xy: tuple[float, float] = (0.6, -0.1)
    # The target bowl's centre is drawn uniformly in this rectangle (35 x 30 cm, paper).
    target_workspace_center: tuple[float, float] = (0.45, 0.28)
    target_workspace_size: tuple[float, float] = (0.35, 0.30)
    # Spoon pose (xyz + quaternion xyzw) before the first action: above the table, outside the bowl.
    spoon_home: tuple[float, float, float, float, float, float, float] = (0.5, 0.0, 0.22, 0.0, 0.0, 0.0, 1.0)
    spoon_mass: float = 0.05
    max_episode_steps: int = 400
    foods_file: str | None = None  # None: the packaged grits_lab/sim/foods.yaml
    # The food's state before the scoop. None: a level fill (every protocol). An azimuth (degrees
    # from the world's +x axis, about the source bowl's axis): the food is packed into that half of
    # the bowl only and settles as a pile heaped against that wall, a state no demonstration shows
    # (`world.pack_in_bowl`).
    heap_azimuth_deg: float | None = None
    cameras: list[CameraConfig] = field(default_factory=_default_cameras)

    def __post_init__(self) -> None:
        require(1e-4 <= self.time_step <= 0.02, "time_step", self.time_step, "in [0.0001, 0.02] seconds")
        require(0 < self.contact_breaking_threshold <= 0.05, "contact_breaking_threshold", self.contact_breaking_threshold, "in (0, 0.05] metres")
        require(self.freeze_distance is None or self.freeze_distance > 0, "freeze_distance", self.freeze_distance, "positive metres, or null")
        require(1 <= self.solver_iterations <= MAX_SOLVER_ITERATIONS, "solver_iterations", self.solver_iterations,
                f"in [1, {MAX_SOLVER_ITERATIONS}]")
        require(0 < self.control_hz <= 100, "control_hz", self.control_hz, "in (0, 100]")
        require(self.ik_per_action >= 1, "ik_per_action", self.ik_per_action, ">= 1")
        require(self.joint_speed_cap is None or self.joint_speed_cap > 0, "joint_speed_cap", self.joint_speed_cap,
                "a positive multiple of the Panda's joint velocity limits, or null")
        require(0 < self.settle_min_s <= self.settle_max_s, "settle_min_s", self.settle_min_s, "in (0, settle_max_s]")
        require(self.settle_speed > 0, "settle_speed", self.settle_speed, "positive")
        require(self.spoon_mass > 0, "spoon_mass", self.spoon_mass, "positive")
        require(self.heap_azimuth_deg is None or -360.0 <= self.heap_azimuth_deg <= 360.0, "heap_azimuth_deg",
                self.heap_azimuth_deg, "degrees in [-360, 360], or null for a level fill")
        require(self.max_episode_steps >= 1, "max_episode_steps", self.max_episode_steps, ">= 1")
        require(all(s > 0 for s in self.target_workspace_size), "target_workspace_size", self.target_workspace_size, "positive")
        require(len({c.name for c in self.cameras}) == len(self.cameras), "cameras", [c.name for c in self.cameras], "uniquely named")
        steps = 1.0 / (self.control_hz * self.time_step)
        require(abs(steps - round(steps)) < 1e-6, "control_hz", self.control_hz, "a rate whose period is a whole number of time steps")
        require(self.ik_per_action <= self.substeps, "ik_per_action", self.ik_per_action,
                f"at most the physics steps per action ({self.substeps}), so that every piece is tracked for at least one")

    @property
    def substeps(self) -> int:
        """Physics steps per action."""
        return steps_per_action(self.control_hz, self.time_step)
