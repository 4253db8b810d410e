"""Point clouds from the simulated cameras: back-projection, CAD sampling, farthest-point sampling, composites.

Pure numpy/open3d on arrays, no simulator state: the adapter that reads a ScoopEnv lives in
`grits_lab.perception.env_clouds`.
"""

from grits_lab.perception.clouds import (
    depth_to_points,
    farthest_point_sample,
    object_points,
    transform_points,
)
from grits_lab.perception.composite import CloudConfig, CloudBuilder
from grits_lab.perception.noise import DepthNoiseConfig, corrupt_depth

__all__ = [
    "CloudBuilder",
    "CloudConfig",
    "DepthNoiseConfig",
    "corrupt_depth",
    "depth_to_points",
    "farthest_point_sample",
    "object_points",
    "transform_points",
]
