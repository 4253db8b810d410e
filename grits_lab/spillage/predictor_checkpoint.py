"""Predictor checkpoints: weights, config and both normalizers in one file, and loading them for use.

A checkpoint is self-contained: `load_predictor(path)` rebuilds the network from the stored
config, so a guided sampler needs nothing but the file to turn a world-frame cloud and a
trajectory into P(spill).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from grits_lab.config import config_from_dict, config_to_dict
from grits_lab.data.format import RETIRED_CHUNK_KEY, refuse_retired_chunk_key
from grits_lab.data.normalize import ActionNormalizer
from grits_lab.errors import ConfigError, StorageError
from grits_lab.records import CPU_KERNELS
from grits_lab.spillage.predictor_config import PredictorConfig
from grits_lab.spillage.model import CloudNormalizer, SpillagePredictor
from grits_lab.training.checkpoints import load_checkpoint, save_checkpoint
from grits_lab.versions import PROTOCOL, cpu_kernels

CHECKPOINT_FORMAT = "grits-spillage-predictor/1"


@dataclass
class TrainedPredictor:
    """A predictor with the normalizers it was trained with; the object guidance and evaluation use."""

    model: SpillagePredictor
    action_normalizer: ActionNormalizer
    cloud_normalizer: CloudNormalizer
    config: PredictorConfig

    def encode_cloud(self, cloud_world: Any) -> torch.Tensor:
        """World-frame composite cloud (B, 3, N, 3) (numpy or torch) -> (B, D) embedding, without gradient."""
        cloud = torch.as_tensor(np.asarray(cloud_world, dtype=np.float32)) if not isinstance(cloud_world, torch.Tensor) else cloud_world.float()
        if cloud.ndim == 3:
            cloud = cloud[None]
        with torch.no_grad():
            return self.model.encode_cloud(self.cloud_normalizer.normalize(cloud))

    def spill_probability(self, traj_norm: torch.Tensor, cloud_embedding: torch.Tensor) -> torch.Tensor:
        """(B, L, 9) trajectory in this predictor's normalized space -> (B,) P(spill), differentiable."""
        return self.model.spill_probability(traj_norm, cloud_embedding)

    def predict_world(self, trajectory_world: Any, cloud_world: Any) -> np.ndarray:
        """Convenience: world-frame chunks (B, L, 9) and clouds (B, 3, N, 3) -> (B,) P(spill) as numpy."""
        traj = torch.as_tensor(self.action_normalizer.normalize(np.asarray(trajectory_world, dtype=np.float32)), dtype=torch.float32)
        with torch.no_grad():
            return self.spill_probability(traj, self.encode_cloud(cloud_world)).numpy()


def save_predictor(path: str | Path, *, config: PredictorConfig, model: SpillagePredictor, action_normalizer: ActionNormalizer, cloud_normalizer: CloudNormalizer, extra: dict[str, Any] | None = None) -> None:
    """Write the checkpoint atomically (a crash mid-write leaves the previous one intact)."""
    payload = {
        "format": CHECKPOINT_FORMAT,
        "protocol": PROTOCOL,  # the task protocol of the code that trained it (docs/protocol.md)
        CPU_KERNELS: cpu_kernels(),  # what trained it: weights trained on other kernels differ (docs/evaluation.md)
        "config": config_to_dict(config),
        "model": model.state_dict(),
        "action_normalizer": action_normalizer.state_dict(),
        "cloud_normalizer": cloud_normalizer.state_dict(),
        **(extra or {}),
    }
    save_checkpoint(path, payload)


def read_checkpoint(path: str | Path) -> dict[str, Any]:
    """The checkpoint's payload; StorageError if it is not a predictor checkpoint, ConfigError if its
    config calls the chunk length `model.chunk_len` (trained before scoop-v4)."""
    payload = load_checkpoint(path)
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise StorageError(f"{path} is not a spillage predictor checkpoint")
    config = payload.get("config")
    model = config.get("model") if isinstance(config, dict) else None
    if isinstance(model, dict):
        refuse_retired_chunk_key(model, path, f"model.{RETIRED_CHUNK_KEY}", "train the predictor again under the current protocol")
    return payload


def load_predictor(path: str | Path, for_inference: bool = True) -> TrainedPredictor:
    """Rebuild a trained predictor; `for_inference` puts it in eval mode with frozen weights."""
    payload = read_checkpoint(path)
    try:
        config = config_from_dict(PredictorConfig, payload["config"])
    except ConfigError as exc:
        raise StorageError(f"{path}: stored config is invalid: {exc}") from None
    model = SpillagePredictor(config.model)
    model.load_state_dict(payload["model"])
    predictor = TrainedPredictor(
        model=model,
        action_normalizer=ActionNormalizer().load_state_dict(payload["action_normalizer"]),
        cloud_normalizer=CloudNormalizer().load_state_dict(payload["cloud_normalizer"]),
        config=config,
    )
    if for_inference:
        model.eval()
        model.requires_grad_(False)
    return predictor
