"""The simulated scooping world: PyBullet scene, food library, robot with spoon, cameras, episode metrics.

No torch and no Ray here: everything runs in a plain process, one PyBullet client per env.
"""

from grits_lab.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    "config": ["CameraConfig", "SimConfig"],
    "env": ["SceneGeometry", "ScoopEnv", "matrix_to_pose9", "pose9_to_matrix"],
    "episode": ["EpisodeRecord", "load_trajectory", "play_trajectory", "run_episode", "validate_trajectory"],
    "expert": ["expert_trajectory", "nominal_expert_trajectory"],
    "foods": ["FoodLibrary", "FoodSpec", "ParticleComponent", "load_foods", "primitive_food"],
})
