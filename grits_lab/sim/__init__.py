"""The simulated scooping world: PyBullet scene, food library, robot with spoon, cameras, episode metrics.

No torch and no Ray here: everything runs in a plain process, one PyBullet client per env.
"""

from grits_lab.sim.config import CameraConfig, SimConfig
from grits_lab.sim.env import SceneGeometry, ScoopEnv, matrix_to_pose9, pose9_to_matrix
from grits_lab.sim.episode import EpisodeRecord, load_trajectory, play_trajectory, run_episode, validate_trajectory
from grits_lab.sim.expert import expert_trajectory, nominal_expert_trajectory
from grits_lab.sim.foods import FoodLibrary, FoodSpec, ParticleComponent, load_foods, primitive_food

__all__ = [
    "CameraConfig",
    "EpisodeRecord",
    "FoodLibrary",
    "FoodSpec",
    "ParticleComponent",
    "SceneGeometry",
    "ScoopEnv",
    "SimConfig",
    "expert_trajectory",
    "load_foods",
    "load_trajectory",
    "matrix_to_pose9",
    "nominal_expert_trajectory",
    "play_trajectory",
    "pose9_to_matrix",
    "primitive_food",
    "run_episode",
    "validate_trajectory",
]
