"""grits_lab: spillage-aware guided diffusion for robot food scooping, in PyBullet."""

__version__ = "0.1.0"
