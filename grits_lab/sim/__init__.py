"""The simulated scooping world: PyBullet scene, food library, robot with spoon, cameras, episode metrics.

No torch and no Ray here: everything runs in a plain process, one PyBullet client per env.
Importing this package registers the Gymnasium env "grits_lab/Scoop-v12" (grits_lab/sim/gym_env.py).
"""

import gymnasium

from grits_lab.sim.env import SceneGeometry, ScoopEnv, matrix_to_pose9, pose9_to_matrix
from grits_lab.sim.expert import expert_trajectory, nominal_expert_trajectory
from grits_lab.sim.foods import FoodLibrary, FoodSpec, ParticleComponent, ParticleRanges, load_foods, primitive_food
from grits_lab.sim.gym_env import ENV_ID, ScoopGymEnv
from grits_lab.sim.playback import EpisodeRecord, load_trajectory, play_episode, play_trajectory, validate_trajectory
from grits_lab.sim.sim_config import CameraConfig, SimConfig

__all__ = [
    "ENV_ID",
    "CameraConfig",
    "EpisodeRecord",
    "FoodLibrary",
    "FoodSpec",
    "ParticleComponent",
    "ParticleRanges",
    "SceneGeometry",
    "ScoopEnv",
    "ScoopGymEnv",
    "SimConfig",
    "expert_trajectory",
    "load_foods",
    "load_trajectory",
    "matrix_to_pose9",
    "nominal_expert_trajectory",
    "play_episode",
    "play_trajectory",
    "pose9_to_matrix",
    "primitive_food",
    "validate_trajectory",
]


if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point=ScoopGymEnv, max_episode_steps=SimConfig().max_episode_steps)
