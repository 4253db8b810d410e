"""Settings of the task's stages after the scoop (transfer and pour), shared by the evaluation and the spillage trials' carry.

They live below both jobs (grits_lab/evaluation runs the stages; grits_lab/collection runs them
after a spillage trial's scoop, as its carry) so that each embeds the one class.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from grits_lab.config import require
from grits_lab.sim.sim_config import MAX_SOLVER_ITERATIONS, SimConfig, time_step_expectation


@dataclass
class TransferSettings:
    """Stages 2 and 3: locate the target bowl from the cameras, move there without collision, pour
    (docs/evaluation.md, "The task, stage by stage", gives each value's reason and source)."""

    enabled: bool = True
    clearance: float = 0.06  # metres the spoon keeps above the bowls' rims and the table on the way
    # Peak speed of the spoon while transferring (m/s; commands at the control rate). With the
    # min-jerk profile the mean is 0.53x and the peak acceleration about 0.1 m/s^2 on a 30-40 cm carry.
    max_speed: float = 0.12
    # "min_jerk": every straight segment of the lift and carry, and the pour's roll, goes from rest
    # to rest on the minimum-jerk profile (what a motion planner's time-parameterization gives a
    # robot); "constant": equal steps, full speed from the first action.
    profile: Literal["min_jerk", "constant"] = "min_jerk"
    # How the arm moves between the actions of these stages. "cubic" (scoop-v9): along the C1 cubic
    # spline through them (`geometry.cubic_pose_path`), one IK piece per physics step, so the
    # spoon's velocity is continuous across actions, as a robot's trajectory controller moves
    # between via points. "linear": straight at one speed within each action (`ScoopEnv.step`),
    # which steps the velocity at every action: on the carry the spoon then takes 4.8-5.7 m/s^2 for
    # one physics step where the min-jerk path asks 0.31 (docs/evaluation.md, "A smooth path
    # through the actions"). The scoop is the policies' and is not touched.
    interpolation: Literal["cubic", "linear"] = "cubic"
    level_steps: int = 10  # actions over which the lift turns the spoon level (one sudden turn swings the arm)
    # Actions holding the lifted, level spoon still over the source bowl before the carry: what a
    # loose load sheds there falls back into the source bowl instead of onto the table on the way.
    lift_hold_steps: int = 0
    # "radial": on the way across, turn the spoon to point away from the robot's base over the
    # target (the arm's natural posture there); "keep": keep the scoop's heading, which twists the
    # wrist to its limit for targets off to the side.
    heading: Literal["radial", "keep"] = "radial"
    # Height above the target bowl's rim at which the pour starts (m; negative: below it): of the
    # spoon's tip for a tip pour, of its centre for a roll. At 4 cm the tipped spoon hangs from its
    # tip into the bowl, its back edge about 1.5 cm above the bowl's floor; a roll at 5 mm ends with
    # its lower lip about 2 cm below the rim.
    pour_height: float = 0.04
    # Place the spoon so that the lip the food leaves by, not its centre, is over the target's
    # centre (2.6 cm along the spoon's width): poured food then lands mid-bowl, not by its wall.
    pour_lip_over_centre: bool = True
    # "tip" (scoop-v6): turn the spoon about its tip, food sliding off the lipless tip while the
    # handle and the hand on it stay above the spoon. "roll" (scoop-v5): turn it about its own x
    # axis, food leaving over the side lip; the hand, 11 cm up the steep handle, swings down
    # beside the spoon and onto the table (docs/archive/oracle_transfer_v5).
    pour_axis: Literal["roll", "tip"] = "tip"
    pour_angle_deg: float = 90.0  # turn of the spoon about `pour_axis` to empty it (the roll's was 120)
    # The spoon's heading at the pour, degrees from the one `heading` gives (radial: pointing away
    # from the robot's base). A tip pour turned 90 degrees moves the rising hand sideways, which the
    # arm follows; pointing away, it moves the hand 20 cm farther out, beyond reach for far bowls.
    pour_yaw_deg: float = 90.0
    # Actions of the pour: 3 s, a mean 30 deg/s (the roll's 120 degrees: 40); at the spoon's back,
    # 6 cm from the tip, the peak accelerations are under 0.1 m/s^2, so food slides out under
    # gravity rather than being flung.
    pour_steps: int = 30
    settle_steps: int = 15  # actions holding still after the pour before counting
    # Before moving, check the path and pour on the arm's kinematic copy (grits_lab/sim/env.py
    # `check_path`). With `slow_to_limits`, every action asking a joint to move faster than the
    # Panda's velocity limit (robot.PANDA_MAX_JOINT_VELOCITY) is slowed (cut into more actions, at
    # most `max_slowdown` per planned action); a motion that still exceeds it is a change of arm
    # posture and fails. Without it, a motion fails when a joint steps more than `max_joint_step`
    # rad in one action. A motion that fails, or holds an unreachable pose, is replaced by the
    # first alternative that passes: the lift with `alternative_level_steps` and the level spoon
    # turned by `alternative_level_yaw_deg`, the pour from `alternative_pour_heights` and moved
    # `alternative_pour_offsets` metres away from the robot's base (negative: towards it), turned by
    # `alternative_pour_yaw_deg`.
    # At most `max_checks` options (a few seconds each on one core with `interpolation: cubic`, which
    # checks the spline's pieces one a physics step; more when slowed).
    reach_check: bool = True
    # The IK's null-space pull towards the arm's rest posture in these stages. Off: the arm follows
    # the path with the least joint motion; on (as in the scoop, and in the transfer before its
    # min-jerk version), an arm far from its rest posture swings shoulder against upper arm in
    # one action however slowly it moves (measured 0.34 rad in 0.1 s, 1.6x the Panda's limit).
    rest_pull: bool = False
    # Every IK solve in these stages that PyBullet's solver fails (out of the IK tolerance) is tried
    # again by damped least squares from where the arm is (`PandaKinematics.refine`), as a robot's
    # Cartesian controller follows a path. Off (scoop-v9 and earlier): PyBullet's answer alone,
    # which stalled 1-4 cm into the lift of 3 of the scoop-v9 oracle's 9 held transfers; of the
    # other 6, the one traced held because the scoop left the wrist at its joint limits
    # (docs/evaluation.md).
    ik_refine: bool = True
    # When no option passes with the scoop's heading (or one of `alternative_level_yaw_deg`), the
    # options again with the lift's heading about the vertical left to the arm, which spends the
    # freedom on unwinding its wrist from its joint limits as the spoon rises and levels
    # (`ScoopEnv.heading_free_path`; the carry starts from the heading the lift ends with), with
    # `max_checks` checks of their own (scoop-v11). Traced under scoop-v10: the scoop left the
    # wrist wound towards its limits and levelling the spoon with its heading fixed asked for more
    # (docs/evaluation.md). False: scoop-v10's options only.
    heading_free_lift: bool = True
    slow_to_limits: bool = True
    # With the reach check: an option whose arm (not the spoon) comes within 5 mm of the table or a
    # bowl on the kinematic copy fails too, as a motion planner's collision check fails it. The
    # roll's options touched on nearly every target (its hand swings onto the table), so scoop-v5
    # ran them with this off; the tip pour keeps the hand up. `transfer_arm_contact_steps` counts
    # the actions the arm touched.
    avoid_arm_contact: bool = True
    max_slowdown: int = 8
    max_joint_step: float = 0.5
    alternative_level_steps: list[int] = field(default_factory=lambda: [30])
    alternative_level_yaw_deg: list[float] = field(default_factory=lambda: [-60.0, 60.0, -90.0, 90.0])
    alternative_pour_heights: list[float] = field(default_factory=lambda: [0.06])
    alternative_pour_offsets: list[float] = field(default_factory=lambda: [0.03, -0.03])
    alternative_pour_yaw_deg: list[float] = field(default_factory=lambda: [-90.0, 135.0, -135.0])
    max_checks: int = 16
    # When no option passes: "hold" keeps the loaded spoon where the scoop left it (a planner that
    # finds no motion within the arm's reach and velocity limits does not move; the task fails with
    # nothing delivered); "best" runs the option that went farthest, unreachable poses and all
    # (scoop-v3's behaviour; its joint jumps throw the load).
    no_option: Literal["hold", "best"] = "hold"
    # Constraint-solver iterations per physics step from the lift on (None: the scoop's
    # `sim.solver_iterations`, 30). The loaded spoon hangs from the arm's seven motors through the
    # hand's fixed constraint; at 30 iterations that chain is not solved to rest, the still spoon
    # trembles (0.16 mm/s) and a heap on it creeps and sheds grains that a spoon made static keeps
    # (docs/evaluation.md, "Grains a still spoon loses"). The scoop keeps 30: its datasets and
    # checkpoints were made with it.
    solver_iterations: int | None = 100
    # Physics time step from the lift on, seconds (None: the scoop's `sim.time_step`, 1/120 s). A
    # heap carried on the spoon at under 1 % of gravity's acceleration creeps off it when contacts
    # are resolved in 1/120 s steps and stays at 1/240 s (the authors' code used 1/256 s): on the
    # oracle's 60 high-level episodes 7 lost food in the carry at 1/120 s, 10 with a 3x slower carry
    # and 2 at 1/240 s (docs/archive/oracle_high_physics_fine). The scoop keeps its step, as
    # it keeps its solver iterations: its datasets and checkpoints were made with it. An action
    # keeps its control period and its IK pieces (`sim.substeps` a period); each piece runs over
    # more physics steps (`ScoopEnv.set_time_step`).
    time_step: float | None = 1.0 / 240.0

    def __post_init__(self) -> None:
        require(self.clearance > 0, "transfer.clearance", self.clearance, "positive")
        require(self.max_joint_step > 0, "transfer.max_joint_step", self.max_joint_step, "positive (rad per action)")
        require(self.max_slowdown >= 1, "transfer.max_slowdown", self.max_slowdown, "at least 1")
        require(not self.slow_to_limits or self.reach_check, "transfer.slow_to_limits", self.slow_to_limits,
                "false when `transfer.reach_check` is false (slowing needs the arm's kinematic check)")
        require(self.max_checks >= 1, "transfer.max_checks", self.max_checks, "at least 1")
        require(all(int(n) >= 1 for n in self.alternative_level_steps), "transfer.alternative_level_steps",
                self.alternative_level_steps, "a list of integers >= 1")
        deep = "above -0.03 m (deeper, the rolled spoon meets the bowl's floor)"
        require(self.pour_height > -0.03, "transfer.pour_height", self.pour_height, deep)
        require(all(h > -0.03 for h in self.alternative_pour_heights), "transfer.alternative_pour_heights",
                self.alternative_pour_heights, f"a list of heights {deep}")
        require(self.max_speed > 0, "transfer.max_speed", self.max_speed, "positive")
        require(self.interpolation in ("cubic", "linear"), "transfer.interpolation", self.interpolation, "cubic or linear")
        require(self.pour_axis in ("roll", "tip"), "transfer.pour_axis", self.pour_axis, "roll or tip")
        require(self.pour_steps >= 1, "transfer.pour_steps", self.pour_steps, "at least 1")
        require(self.level_steps >= 1, "transfer.level_steps", self.level_steps, "at least 1")
        require(self.lift_hold_steps >= 0, "transfer.lift_hold_steps", self.lift_hold_steps, "non-negative")
        require(self.solver_iterations is None or 1 <= self.solver_iterations <= MAX_SOLVER_ITERATIONS,
                "transfer.solver_iterations", self.solver_iterations, f"in [1, {MAX_SOLVER_ITERATIONS}], or null for the scoop's")
        require(self.time_step is None or 1e-4 <= self.time_step <= 0.02, "transfer.time_step", self.time_step,
                "in [0.0001, 0.02] seconds, or null for the scoop's `sim.time_step`")

    def require_time_step_fits(self, sim: SimConfig, key: str) -> None:
        """ConfigError naming `key` unless `time_step` is one the episode's `sim` can step at
        (`sim_config.time_step_expectation`): checked where both are known, when a config loads,
        not in every episode's `ScoopEnv.set_time_step`."""
        if self.time_step is not None:
            expectation = time_step_expectation(self.time_step, sim.control_hz, sim.ik_per_action)
            require(expectation is None, key, self.time_step, f"{expectation} (sim.control_hz {sim.control_hz:g})")
