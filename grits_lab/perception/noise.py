"""A depth-sensor error model for the raw point cloud: axial noise growing with range, disparity
quantization, lateral jitter, and dropout at depth edges and at random.

Defaults follow the structured-light / active-stereo sensors used on table-top robots: axial
noise sigma(z) = 1.2 mm + 1.9 mm * (z - 0.4 m)^2 (the Kinect model of Nguyen, Izadi & Lovell,
2012, also a fair fit of RealSense D4xx at 0.3-1 m), disparity quantized to 1/8 pixel with a
5 cm baseline, lateral jitter of ~0.5 px, pixels at depth discontinuities lost half of the time
(mixed pixels and stereo shadows) and 1% lost everywhere. Dropped pixels become 0 (invalid).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grits_lab.config import require


@dataclass
class DepthNoiseConfig:
    axial_base_m: float = 0.0012
    axial_quadratic_m: float = 0.0019  # per (z - axial_center_m)^2, z in metres
    axial_center_m: float = 0.4
    baseline_m: float = 0.05  # stereo baseline for disparity quantization; 0 disables it
    subpixel: float = 0.125  # disparity quantization step (pixels)
    lateral_px: float = 0.5  # std of the lateral pixel jitter
    edge_jump_m: float = 0.01  # a neighbour further than this in depth marks an edge pixel
    edge_dropout: float = 0.5
    random_dropout: float = 0.01
    min_range_m: float = 0.1
    max_range_m: float = 3.0

    def __post_init__(self) -> None:
        for key in ("axial_base_m", "axial_quadratic_m", "baseline_m", "subpixel", "lateral_px", "edge_jump_m"):
            require(getattr(self, key) >= 0, f"noise.{key}", getattr(self, key), "non-negative")
        for key in ("edge_dropout", "random_dropout"):
            require(0 <= getattr(self, key) <= 1, f"noise.{key}", getattr(self, key), "in [0, 1]")
        require(0 <= self.min_range_m < self.max_range_m, "noise.max_range_m", self.max_range_m, "above min_range_m")


def corrupt_depth(depth: np.ndarray, focal_px: float, rng: np.random.Generator, config: DepthNoiseConfig) -> np.ndarray:
    """A noisy copy of a clean (H, W) z-depth image in metres; invalid pixels are 0."""
    clean = np.where(np.isfinite(depth), np.asarray(depth, dtype=np.float64), 0.0)
    h, w = clean.shape
    out = clean
    if config.lateral_px > 0:
        # Lateral error: each pixel reports the depth of a neighbour a fraction of a pixel away.
        dv = np.clip(np.rint(rng.normal(0, config.lateral_px, (h, w))).astype(int) + np.arange(h)[:, None], 0, h - 1)
        du = np.clip(np.rint(rng.normal(0, config.lateral_px, (h, w))).astype(int) + np.arange(w)[None, :], 0, w - 1)
        out = out[dv, du]
    valid = out > 0
    sigma = config.axial_base_m + config.axial_quadratic_m * (out - config.axial_center_m) ** 2
    out = out + rng.normal(0.0, 1.0, (h, w)) * sigma
    if config.baseline_m > 0 and config.subpixel > 0:
        fb = focal_px * config.baseline_m
        disparity = np.where(valid, fb / np.maximum(out, 1e-6), 0.0)
        disparity = np.round(disparity / config.subpixel) * config.subpixel
        out = np.where(disparity > 0, fb / np.maximum(disparity, 1e-9), 0.0)
    edges = _edge_pixels(clean, config.edge_jump_m)
    drop = rng.random((h, w)) < config.random_dropout
    drop |= edges & (rng.random((h, w)) < config.edge_dropout)
    drop |= ~valid | (out < config.min_range_m) | (out > config.max_range_m)
    return np.where(drop, 0.0, out).astype(np.float32)


def _edge_pixels(depth: np.ndarray, jump: float) -> np.ndarray:
    edges = np.zeros(depth.shape, dtype=bool)
    dy = np.abs(np.diff(depth, axis=0)) > jump
    dx = np.abs(np.diff(depth, axis=1)) > jump
    edges[:-1] |= dy
    edges[1:] |= dy
    edges[:, :-1] |= dx
    edges[:, 1:] |= dx
    return edges
