"""The simulated scooping world: PyBullet scene, food library, robot with spoon, cameras, episode metrics.

No torch and no Ray here: everything runs in a plain process, one PyBullet client per env.
Importing this package registers the Gymnasium env "grits_lab/Scoop-v0" (grits_lab/sim/gym_env.py).
"""

from typing import Any

import gymnasium

from grits_lab.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "config": ["CameraConfig", "SimConfig"],
    "env": ["SceneGeometry", "ScoopEnv", "matrix_to_pose9", "pose9_to_matrix"],
    "episode": ["EpisodeRecord", "load_trajectory", "play_episode", "play_trajectory", "validate_trajectory"],
    "expert": ["expert_trajectory", "nominal_expert_trajectory"],
    "foods": ["FoodLibrary", "FoodSpec", "ParticleComponent", "ParticleRanges", "load_foods", "primitive_food"],
    "gym_env": ["ENV_ID", "ScoopGymEnv"],
})


def _make_scoop_gym_env(**kwargs: Any) -> Any:
    # pybullet is imported when an env is made, not when the package is imported.
    from grits_lab.sim.gym_env import ScoopGymEnv

    return ScoopGymEnv(**kwargs)


if "grits_lab/Scoop-v0" not in gymnasium.registry:
    gymnasium.register(id="grits_lab/Scoop-v0", entry_point=_make_scoop_gym_env, max_episode_steps=None)
