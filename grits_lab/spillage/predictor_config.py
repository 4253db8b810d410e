"""Typed configs of the spillage predictor: model, data and training, validated on load.

Defaults are the authors' values where the paper or their code gives one (SPEC.md, "Spillage
predictor"): trajectory of 12 waypoints x 9, per-waypoint MLP 9->16->32, fusion MLP
->256->32->2 with dropout 0.1, lr 1e-3, batch 96, 20 % validation. Choices of ours are
commented where they are made.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from grits_lab.config import require
from grits_lab.data.chunk_labels import Label
from grits_lab.training.metrics_log import TrackingConfig

Encoder = Literal["dp3", "pointnet2"]
# "trajectory_and_cloud" is GRITS; the other two are the baselines of the evidence.
Inputs = Literal["trajectory_and_cloud", "trajectory", "cloud"]
CloudSource = Literal["composite", "raw"]


@dataclass
class DP3EncoderConfig:
    """PointNet-style per-point MLP + max-pool with LayerNorm (no T-Net, no BatchNorm), as DP3."""

    hidden_dims: tuple[int, ...] = (64, 128, 256)
    out_dim: int = 128
    # Object identity enters twice (see docs/predictor.md): a one-hot (food, spoon, bowl) feature on
    # every point, so the shared MLP can treat the three objects differently, and a max-pool per
    # object, so the few food points are never drowned by the bowl's in one global max.
    one_hot_identity: bool = True
    pool_per_object: bool = True

    def __post_init__(self) -> None:
        require(len(self.hidden_dims) >= 1 and all(d > 0 for d in self.hidden_dims), "dp3.hidden_dims", self.hidden_dims, "a non-empty list of positive integers")
        require(self.out_dim > 0, "dp3.out_dim", self.out_dim, "positive")


@dataclass
class SetAbstractionConfig:
    """One PointNet++ set-abstraction level: `n_centroids` by farthest-point sampling, a ball of
    `radius` (normalized cloud units) holding at most `n_neighbors` points, a shared MLP, max-pool."""

    n_centroids: int
    radius: float
    n_neighbors: int
    mlp: tuple[int, ...]

    def __post_init__(self) -> None:
        require(self.n_centroids > 0, "pointnet2.levels.n_centroids", self.n_centroids, "positive")
        require(self.radius > 0, "pointnet2.levels.radius", self.radius, "positive")
        require(self.n_neighbors > 0, "pointnet2.levels.n_neighbors", self.n_neighbors, "positive")
        require(len(self.mlp) >= 1 and all(d > 0 for d in self.mlp), "pointnet2.levels.mlp", self.mlp, "a non-empty list of positive integers")


def _default_levels() -> list[SetAbstractionConfig]:
    # Smaller than the original classification network (512/128 centroids, 1024 features) so
    # that it trains on a CPU; the structure (two SA levels + a global level) is the original's.
    return [
        SetAbstractionConfig(n_centroids=256, radius=0.2, n_neighbors=32, mlp=(32, 32, 64)),
        SetAbstractionConfig(n_centroids=64, radius=0.4, n_neighbors=32, mlp=(64, 64, 128)),
    ]


@dataclass
class PointNet2EncoderConfig:
    """PointNet++ (Qi et al. 2017) single-scale grouping; the ablation encoder of paper Fig. 8."""

    levels: list[SetAbstractionConfig] = field(default_factory=_default_levels)
    global_mlp: tuple[int, ...] = (128, 256)
    out_dim: int = 128
    one_hot_identity: bool = True
    # The original uses BatchNorm; "layer" keeps train and eval behaviour identical at batch 1.
    norm: Literal["batch", "layer"] = "batch"

    def __post_init__(self) -> None:
        require(len(self.levels) >= 1, "pointnet2.levels", self.levels, "at least one level")
        require(all(d > 0 for d in self.global_mlp), "pointnet2.global_mlp", self.global_mlp, "positive integers")
        require(self.out_dim > 0, "pointnet2.out_dim", self.out_dim, "positive")


@dataclass
class PredictorModelConfig:
    encoder: Encoder = "dp3"
    inputs: Inputs = "trajectory_and_cloud"
    n_action_steps: int = 12  # waypoints of a judged chunk: the policy's n_action_steps
    action_dim: int = 9
    waypoint_mlp: tuple[int, ...] = (16, 32)
    fusion_mlp: tuple[int, ...] = (256, 32)
    dropout: float = 0.1
    dp3: DP3EncoderConfig = field(default_factory=DP3EncoderConfig)
    pointnet2: PointNet2EncoderConfig = field(default_factory=PointNet2EncoderConfig)

    def __post_init__(self) -> None:
        require(self.n_action_steps > 0, "model.n_action_steps", self.n_action_steps, "positive")
        require(self.action_dim == 9, "model.action_dim", self.action_dim, "9 (xyz + 6-D rotation)")
        require(len(self.waypoint_mlp) >= 1 and all(d > 0 for d in self.waypoint_mlp), "model.waypoint_mlp", self.waypoint_mlp, "positive integers")
        require(len(self.fusion_mlp) >= 1 and all(d > 0 for d in self.fusion_mlp), "model.fusion_mlp", self.fusion_mlp, "positive integers")
        require(0.0 <= self.dropout < 1.0, "model.dropout", self.dropout, "in [0, 1)")


@dataclass
class PredictorDataConfig:
    # A spillage dataset directory, or a list of them trained on together (each split into train and
    # validation on its own: docs/predictor.md, "Training on several datasets").
    dataset: str | list[str] = "results/datasets/spillage_quick"
    # What a chunk's label says (docs/predictor.md, "Which label"): "chunk", the paper's, whether the
    # spilled count rose during the chunk's own n_action_steps actions; "horizon", whether food
    # spilled from its first action until the load was delivered (needs a dataset collected with
    # horizon labels: every spillage dataset since they were added; exit.kind carry to see the carry).
    label: Label = "chunk"
    cloud_source: CloudSource = "composite"
    # Points kept per object: a random subset of the stored N (fresh each training epoch, fixed
    # at evaluation); null keeps all. CPU presets use fewer points than the paper's 3,000.
    points_per_object: int | None = None
    val_fraction: float = 0.2
    # Episodes of this particle shape all go to validation (generalization to an unseen shape).
    holdout_shape: str | None = None
    split_seed: int = 0
    # Decoded episodes kept in memory after the first epoch; turn off for datasets larger than RAM.
    cache_episodes: bool = True
    shuffle_buffer: int = 2048
    # Reference scale (metres) of the cloud normalization: the source bowl is ~17 cm across, so
    # coordinates relative to its centre divided by 0.1 lie within about [-1, 1].
    cloud_scale: float = 0.1

    def _listed(self) -> list[str]:
        return self.dataset if isinstance(self.dataset, list) else [self.dataset]

    @property
    def dataset_dirs(self) -> list[Path]:
        """`dataset` as a list of directories (one entry when it names one)."""
        return [Path(d) for d in self._listed()]

    def __post_init__(self) -> None:
        listed = self._listed()
        require(bool(listed) and all(listed), "data.dataset", self.dataset, "a dataset directory or a non-empty list of them")
        require(self.points_per_object is None or self.points_per_object > 0, "data.points_per_object", self.points_per_object, "positive or null")
        require(0.0 < self.val_fraction < 1.0, "data.val_fraction", self.val_fraction, "in (0, 1)")
        require(self.shuffle_buffer > 0, "data.shuffle_buffer", self.shuffle_buffer, "positive")
        require(self.cloud_scale > 0, "data.cloud_scale", self.cloud_scale, "positive")


@dataclass
class PredictorTrainConfig:
    epochs: int = 30
    batch_size: int = 96
    lr: float = 1e-3
    weight_decay: float = 0.0
    # Class weights of the cross-entropy (docs/predictor.md, "Class weighting"). "none": every chunk
    # weighs 1, as the paper, whose dataset is balanced by trial (2,000 spill / 2,000 no spill).
    # "balanced": each class weighs n / (2 n_class) over the training chunks, so a set where few
    # chunks spill cannot be fit by predicting "no spill" everywhere; P(spill) is then calibrated to
    # a 50 % prior instead of the training set's share of spilling chunks.
    class_weight: Literal["none", "balanced"] = "none"
    seed: int = 0
    num_threads: int = 2
    select_metric: Literal["val_loss", "val_auroc"] = "val_loss"
    ece_bins: int = 10
    tracking: TrackingConfig = field(default_factory=TrackingConfig)  # MLflow besides metrics.csv (grits_lab/training/metrics_log.py)

    def __post_init__(self) -> None:
        require(self.epochs > 0, "train.epochs", self.epochs, "positive")
        require(self.batch_size > 0, "train.batch_size", self.batch_size, "positive")
        require(self.lr > 0, "train.lr", self.lr, "positive")
        require(self.weight_decay >= 0, "train.weight_decay", self.weight_decay, "non-negative")
        require(self.num_threads > 0, "train.num_threads", self.num_threads, "positive")
        require(self.ece_bins > 1, "train.ece_bins", self.ece_bins, "greater than 1")


@dataclass
class PredictorConfig:
    """One predictor experiment: `grits-lab train predictor experiments/<name>.yaml`."""

    name: str = "predictor"
    output_dir: str = "results/predictor"
    model: PredictorModelConfig = field(default_factory=PredictorModelConfig)
    data: PredictorDataConfig = field(default_factory=PredictorDataConfig)
    train: PredictorTrainConfig = field(default_factory=PredictorTrainConfig)

    def __post_init__(self) -> None:
        require(bool(self.name) and "/" not in self.name, "name", self.name, "a non-empty name without '/'")
