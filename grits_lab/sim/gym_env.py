"""`ScoopGymEnv`: the scooping world as a registered `gymnasium.Env` ("grits_lab/Scoop-v12").

    import gymnasium, grits_lab.sim
    env = gymnasium.make("grits_lab/Scoop-v12", food="prune", level="low", render_mode="rgb_array")
    obs, info = env.reset(seed=0)

It is a `ScoopEnv` (every query of the simulator stays available through `env.unwrapped`) with
the declared spaces, Gymnasium's seeding and rendering:

- action, `action_mode="relative"` (the default): Box(-1, 1, (6,), float32), a move of the
  spoon from its last commanded pose in normalized units: xyz times `RELATIVE_SCALE.translation_m`
  (1 cm; 0.1 m/s at 10 Hz) in the world frame, then a rotation vector times
  `RELATIVE_SCALE.rotation_rad` (0.05 rad) about the spoon's centre, world axes. The position is
  clipped to `WORKSPACE` (both bowls and the air above them) and a rotation that would tilt the
  spoon more than `MAX_TILT_RAD` from its home pose is not applied, so a random agent stays
  where the arm reaches (`tests/sim/test_gym_env.py` measures its IK failure rate).
- action, `action_mode="absolute"`: Box(-1, 1, (9,), float32): the spoon pose target, xyz in
  metres in the world frame (the arm reaches 0.86 m, so every reachable target lies in the box)
  + the 6-D rotation (two unit columns of the rotation matrix, entries in [-1, 1]); what
  `ScoopEnv.step` and the recorded trajectories take. Poses the arm cannot reach are counted
  as IK failures (`info["ik_failures"]`), never raised.
- observation: Dict(ee_pose: Box(-1.5, 1.5, (9,), float32) measured spoon pose, same layout;
  joint_pos: Box(-2 pi, 2 pi, (7,), float32) arm joint angles in radians).
- reward: minus the particles newly spilled in the step; `terminated` is always False,
  `truncated` after `SimConfig.max_episode_steps` actions (400; also the registration's
  `max_episode_steps`, so `env.spec.max_episode_steps` says it).
- info, after reset and every step: `ScoopEnv`'s step info (`spilled`, `ik_failure`,
  `ik_failures`, `joint_step`, ...) and `info["metrics"]`, the scoop and spill metrics of
  `ScoopEnv.metrics()` (`spilled`, `scooped`, `in_spoon`, `spoon_coverage`, `scoop_success`, ...).
- `reset(seed=s)` builds the very world `ScoopEnv.reset(seed=s)` builds (the recorded episode
  seeds work unchanged) and reseeds `np_random`; `reset(seed=None)` draws the episode seed
  from `np_random`, so a sequence of resets after one seeded reset is reproducible.
- `render()` with `render_mode="rgb_array"`: (360, 480, 3) uint8 from the video camera
  (grits_lab/sim/video.py), which shows the spoon and both bowls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from grits_lab.geometry import axis_angle_matrix
from grits_lab.versions import ENV_VERSION
from grits_lab.sim.sim_config import SimConfig
from grits_lab.sim.env import DEFAULT_FOOD, ScoopEnv, matrix_to_pose9, pose9_to_matrix

ENV_ID = f"grits_lab/Scoop-v{ENV_VERSION}"  # the scoop env's own version (grits_lab/versions.py)
N_JOINTS = 7
ACTION_MODES = ("relative", "absolute")


@dataclass(frozen=True)
class RelativeScale:
    """What an action entry of 1 moves in relative mode, per action (0.1 s at 10 Hz)."""

    translation_m: float = 0.01
    rotation_rad: float = 0.05


RELATIVE_SCALE = RelativeScale()
# World-frame box (m) the relative mode keeps the spoon in: the source bowl at (0.6, -0.1), the
# target bowl's workspace (0.45 +- 0.175, 0.28 +- 0.15) and the air above them, all within reach.
WORKSPACE = (np.array([0.3, -0.3, 0.01]), np.array([0.8, 0.45, 0.4]))
MAX_TILT_RAD = 1.2  # the spoon turns at most this far from its home orientation in relative mode


RELATIVE_AXES = ("dx", "dy", "dz", "rx", "ry", "rz")  # the entries of a relative action


class ScoopGymEnv(ScoopEnv, gym.Env):
    """The scooping task behind `gymnasium.Env`; see the module docstring for spaces and seeding.

    food, level: the episode's food and quantity level (a reset's `options` may override them);
    InputError on the first reset if unknown. config: the world's SimConfig (default SimConfig()).
    action_mode: "relative" (6-D moves in [-1, 1], the default) or "absolute" (9-D poses).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, food: str = DEFAULT_FOOD, level: str | None = None, config: SimConfig | None = None,
                 render_mode: str | None = None, action_mode: str = "relative") -> None:
        ScoopEnv.__init__(self, config)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        if action_mode not in ACTION_MODES:
            raise ValueError(f"action_mode must be one of {', '.join(ACTION_MODES)}, got {action_mode!r}")
        self.action_mode = action_mode
        spec = self.foods.get(food)  # InputError now, not at the first reset
        self.default_food = food
        self.default_level = level if level is not None else next(iter(spec.levels))
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": int(self.config.control_hz)}
        self.action_space = spaces.Box(-1.0, 1.0, shape=(6 if action_mode == "relative" else 9,), dtype=np.float32)
        self.observation_space = spaces.Dict({
            "ee_pose": spaces.Box(-1.5, 1.5, shape=(9,), dtype=np.float32),
            "joint_pos": spaces.Box(-2 * math.pi, 2 * math.pi, shape=(N_JOINTS,), dtype=np.float32),
        })

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Build and settle a new world; options as `ScoopEnv.reset` (food and level default to the constructor's)."""
        gym.Env.reset(self, seed=seed)
        episode_seed = int(seed) if seed is not None else int(self.np_random.integers(2**31))
        options = dict(options or {})
        defaults = {} if "food_spec" in options else {"food": self.default_food, "level": self.default_level}
        merged = {**defaults, **options}
        if "food" in options and "level" not in options:
            merged.pop("level")  # the given food's first level, as in ScoopEnv.reset
        obs, info = ScoopEnv.reset(self, seed=episode_seed, options=merged)
        self._home_rotation = self._pose_target[:3, :3].copy()
        return obs, {**info, "metrics": self.metrics()}

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """One action (a relative move or an absolute pose, by `action_mode`) for 1 / control_hz s, or
        longer when slowed to the Panda's joint limits (info["slowdown"], ScoopEnv.step)."""
        pose = self.relative_target(action) if self.action_mode == "relative" else action
        obs, reward, terminated, truncated, info = ScoopEnv.step(self, pose)
        return obs, reward, terminated, truncated, {**info, "metrics": self.metrics()}

    def relative_target(self, action: np.ndarray) -> np.ndarray:
        """The 9-D pose a relative action (6,) commands: the last commanded pose moved and turned
        by the scaled action, clipped to WORKSPACE; a turn past MAX_TILT_RAD from home is dropped.
        Finite entries outside [-1, 1] are clipped to it (the action space's bounds); ValueError for
        another shape or a NaN or infinite entry, naming the entry of the 6 sent."""
        raw = np.asarray(action, dtype=np.float64).reshape(-1)
        if raw.shape != (6,):
            raise ValueError(f"a relative action is 6 numbers in [-1, 1] (dx, dy, dz, rx, ry, rz), got shape {raw.shape}")
        bad = np.flatnonzero(~np.isfinite(raw))
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"a relative action is 6 finite numbers in [-1, 1] (dx, dy, dz, rx, ry, rz); entry {i} "
                             f"({RELATIVE_AXES[i]}) is {raw[i]} in {raw.tolist()}")
        a = np.clip(raw, -1.0, 1.0)
        current = self._pose_target
        target = current.copy()
        target[:3, 3] = np.clip(current[:3, 3] + RELATIVE_SCALE.translation_m * a[:3], *WORKSPACE)
        turn = RELATIVE_SCALE.rotation_rad * a[3:]
        angle = float(np.linalg.norm(turn))
        if angle > 1e-12:
            rotated = axis_angle_matrix(turn, angle) @ current[:3, :3]
            tilt = math.acos(np.clip((np.trace(self._home_rotation.T @ rotated) - 1) / 2, -1.0, 1.0))
            if tilt <= MAX_TILT_RAD:
                target[:3, :3] = rotated
        return matrix_to_pose9(target)

    def render(self) -> np.ndarray | None:
        """(H, W, 3) uint8 from the video camera when render_mode is "rgb_array"; None otherwise."""
        if self.render_mode != "rgb_array":
            return None
        from grits_lab.sim.video import render_frame

        return render_frame(self)

    def close(self) -> None:
        ScoopEnv.close(self)
        gym.Env.close(self)
