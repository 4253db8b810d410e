"""`ScoopGymEnv`: the scooping world as a registered `gymnasium.Env` ("grits_lab/Scoop-v0").

    import gymnasium, grits_lab.sim
    env = gymnasium.make("grits_lab/Scoop-v0", food="prune", level="low", render_mode="rgb_array")
    obs, info = env.reset(seed=0)

It is a `ScoopEnv` (every query of the simulator stays available through `env.unwrapped`) with
the declared spaces, Gymnasium's seeding and rendering:

- action: Box(-1, 1, (9,), float32): the spoon pose target, xyz in metres in the robot base
  frame (the arm reaches 0.86 m, so every reachable target lies in the box) + the 6-D rotation
  (two unit columns of the rotation matrix, entries in [-1, 1]). Poses the arm cannot reach
  are counted as IK failures (`info["ik_failures"]`), never raised.
- observation: Dict(ee_pose: Box(-1.5, 1.5, (9,), float32) measured spoon pose, same layout;
  joint_pos: Box(-2 pi, 2 pi, (7,), float32) arm joint angles in radians).
- reward: minus the particles newly spilled in the step; `terminated` is always False,
  `truncated` after `SimConfig.max_episode_steps` actions.
- `reset(seed=s)` builds the very world `ScoopEnv.reset(seed=s)` builds (the recorded episode
  seeds work unchanged) and reseeds `np_random`; `reset(seed=None)` draws the episode seed
  from `np_random`, so a sequence of resets after one seeded reset is reproducible.
- `render()` with `render_mode="rgb_array"`: (360, 480, 3) uint8 from the video camera
  (grits_lab/sim/video.py), which shows the spoon and both bowls.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from grits_lab.sim.sim_config import SimConfig
from grits_lab.sim.env import DEFAULT_FOOD, ScoopEnv

ENV_ID = "grits_lab/Scoop-v0"
N_JOINTS = 7


class ScoopGymEnv(ScoopEnv, gym.Env):
    """The scooping task behind `gymnasium.Env`; see the module docstring for spaces and seeding.

    food, level: the episode's food and quantity level (a reset's `options` may override them);
    InputError on the first reset if unknown. config: the world's SimConfig (default SimConfig()).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, food: str = DEFAULT_FOOD, level: str | None = None, config: SimConfig | None = None,
                 render_mode: str | None = None) -> None:
        ScoopEnv.__init__(self, config)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        spec = self.foods.get(food)  # InputError now, not at the first reset
        self.default_food = food
        self.default_level = level if level is not None else next(iter(spec.levels))
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": int(self.config.control_hz)}
        self.action_space = spaces.Box(-1.0, 1.0, shape=(9,), dtype=np.float32)
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
        return ScoopEnv.reset(self, seed=episode_seed, options=merged)

    def render(self) -> np.ndarray | None:
        """(H, W, 3) uint8 from the video camera when render_mode is "rgb_array"; None otherwise."""
        if self.render_mode != "rgb_array":
            return None
        from grits_lab.sim.video import render_frame

        return render_frame(self)

    def close(self) -> None:
        ScoopEnv.close(self)
        gym.Env.close(self)
