"""Training and evaluation of the spillage predictor: epochs with validation metrics, checkpoints, resume.

A run lives in `<output_dir>/<name>/`: `last.pt` (written after every epoch, what a resumed run
continues from), `best.pt` (the epoch with the best validation score by `train.select_metric`),
`history.json` (one row per epoch: loss, accuracy, AUROC, ECE on train and validation) and
`config.yaml`. A rerun with the same config resumes after the last finished epoch; a changed
config refuses to resume unless the run is restarted.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch
import yaml
from torch.utils.data import DataLoader

from grits_lab.config import config_fingerprint, config_to_dict
from grits_lab.data.chunk_labels import LABEL_ARRAYS, LABELS
from grits_lab.data.normalize import ActionNormalizer
from grits_lab.errors import ConfigError, InputError
from grits_lab.io import ensure_writable_dir, exclusive_directory, write_json_atomic, write_text_atomic
from grits_lab.seeding import derive_seed
from grits_lab.spillage.predictor_checkpoint import TrainedPredictor, read_checkpoint, save_predictor
from grits_lab.spillage.predictor_config import PredictorConfig
from grits_lab.spillage.chunk_dataset import CLOUD_KEYS, EpisodeSplit, SpillageChunkDataset, check_spillage_dataset, fit_normalizers, split_training_datasets
from grits_lab.spillage.classifier_metrics import classification_report, degenerate_reason
from grits_lab.training.metrics_log import MetricLogger
from grits_lab.spillage.model import CloudNormalizer, SpillagePredictor
from grits_lab.training.metrics_log import require_finite_loss


def run_dir(config: PredictorConfig) -> Path:
    return Path(config.output_dir) / config.name


def _resume_fingerprint(config: PredictorConfig) -> str:
    """Fingerprint of everything that must match to resume (`train.epochs` may grow: train longer)."""
    described = config_to_dict(config)
    del described["train"]["epochs"]
    del described["train"]["tracking"]  # where the metrics are shown, not what is trained
    if described["data"]["label"] == "chunk":  # the only label before the key existed: those runs still resume
        del described["data"]["label"]
    if described["train"]["class_weight"] == "none":  # likewise for runs from before class weighting
        del described["train"]["class_weight"]
    return config_fingerprint(described)


def class_weights(labels: np.ndarray, mode: str) -> torch.Tensor | None:
    """Cross-entropy weights (no spill, spill) for `train.class_weight`: None for "none"; for "balanced"
    n / (2 n_c) over `labels` (shape (N,), 0/1), so each class carries half the loss. InputError when a
    class is absent (nothing to balance)."""
    if mode == "none":
        return None
    labels = np.asarray(labels).astype(np.int64).reshape(-1)
    counts = np.bincount(labels, minlength=2)[:2]
    if (counts == 0).any():
        raise InputError(f"train.class_weight: balanced needs both classes in the training chunks; got {counts[0]} safe "
                         f"and {counts[1]} spilling")
    return torch.tensor(len(labels) / (2.0 * counts), dtype=torch.float32)


def _loader(dataset: SpillageChunkDataset, batch_size: int) -> DataLoader:
    # num_workers=0: the machine has two cores, and the model's own threads use them.
    return DataLoader(dataset, batch_size=batch_size, num_workers=0)


def predict(model: SpillagePredictor, dataset: SpillageChunkDataset, batch_size: int = 256,
            weight: torch.Tensor | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """P(spill) and labels over the dataset in its (fixed) order, and the mean cross-entropy (with
    class weights `weight` (2,), the weighted mean, as the training loss takes it)."""
    model.eval()
    probs, labels, losses, weights = [], [], [], []
    with torch.no_grad():
        for traj, cloud, label in _loader(dataset, batch_size):
            logits = model(traj, cloud)
            losses.append(torch.nn.functional.cross_entropy(logits, label, weight=weight, reduction="sum").item())
            weights.append(float(weight[label].sum()) if weight is not None else float(len(label)))
            probs.append(torch.softmax(logits, dim=-1)[:, 1].numpy())
            labels.append(label.numpy())
    p = np.concatenate(probs) if probs else np.zeros(0)
    y = np.concatenate(labels) if labels else np.zeros(0)
    return p, y, float(sum(losses) / max(sum(weights), 1e-12))


def _untimed(history: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The history a checkpoint stores: every metric but the epochs' wall-clock `seconds`, so that the
    same config on the same data writes a byte-identical checkpoint (its digest names it in provenance)."""
    return [{k: v for k, v in row.items() if k != "seconds"} for row in history]


def _timed_history(path: Path, history: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The checkpoint's `history` with the epochs' `seconds` put back from history.json, when that file
    holds the same epochs (it is written after each checkpoint); else the checkpoint's as it is."""
    if not path.exists():
        return history
    try:
        timed = json.loads(path.read_text())
    except (OSError, ValueError):
        return history
    if len(timed) < len(history) or [r.get("epoch") for r in timed[: len(history)]] != [r["epoch"] for r in history]:
        return history
    return timed[: len(history)]


def train_predictor(config: PredictorConfig, restart: bool = False, progress: bool = True) -> dict[str, Any]:
    """Train (or resume) the run of `config`; returns the best epoch's validation metrics and paths."""
    torch.set_num_threads(config.train.num_threads)
    data = config.data
    dataset_dir, split = split_training_datasets(data.dataset_dirs, data.val_fraction, data.split_seed, data.holdout_shape,
                                                 n_action_steps=config.model.n_action_steps, label=data.label)
    out = ensure_writable_dir(run_dir(config))
    with exclusive_directory(out, "train predictor"):  # one trainer per run: two would overwrite each other's last.pt
        return _train_in(out, config, dataset_dir, split, restart, progress)


def _train_in(out: Path, config: PredictorConfig, dataset_dir: Path, split: EpisodeSplit, restart: bool, progress: bool) -> dict[str, Any]:
    from tqdm import tqdm

    fingerprint = _resume_fingerprint(config)
    last_path, best_path = out / "last.pt", out / "best.pt"
    cloud_key = CLOUD_KEYS[config.data.cloud_source]

    torch.manual_seed(derive_seed(config.train.seed, "predictor-init"))
    model = SpillagePredictor(config.model)
    optimizer = torch.optim.AdamW(model.parameters(), lr=config.train.lr, weight_decay=config.train.weight_decay)
    history: list[dict[str, Any]] = []
    start_epoch = 0
    best_score = math.inf
    state = read_checkpoint(last_path) if last_path.exists() and not restart else None
    if state is not None:
        if state.get("fingerprint") != fingerprint:
            raise ConfigError(f"{last_path} was trained with a different config (only `train.epochs` may change on resume); pass --restart to start over")
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        action_norm = ActionNormalizer().load_state_dict(state["action_normalizer"])
        cloud_norm = CloudNormalizer().load_state_dict(state["cloud_normalizer"])
        history, start_epoch, best_score = state["history"], int(state["epoch"]) + 1, float(state["best_score"])
        history = _timed_history(out / "history.json", history)
    else:
        action_norm, cloud_norm = fit_normalizers(dataset_dir, split.train, cloud_key, config.data.cloud_scale)
    write_text_atomic(out / "config.yaml", yaml.safe_dump(config_to_dict(config), sort_keys=False))

    common = dict(cloud_key=cloud_key, n_action_steps=config.model.n_action_steps, action_normalizer=action_norm, cloud_normalizer=cloud_norm, points_per_object=config.data.points_per_object, seed=config.train.seed, cache=config.data.cache_episodes, label_key=LABEL_ARRAYS[config.data.label])
    train_set = SpillageChunkDataset(dataset_dir, split.train, shuffle=True, buffer_size=config.data.shuffle_buffer, **common)
    train_eval_set = SpillageChunkDataset(dataset_dir, split.train, shuffle=False, **common)
    train_eval_set._cache = train_set._cache  # one decoded copy of each training episode
    val_set = SpillageChunkDataset(dataset_dir, split.val, shuffle=False, **common)
    n_train = len(train_set.labels())
    weight = class_weights(train_set.labels(), config.train.class_weight)

    logger = MetricLogger(out, namespace="predictor", resume_step=start_epoch, title=f"predictor {out.name}",  # one step per epoch
                          tracking=config.train.tracking, params=config_to_dict(config))
    for epoch in range(start_epoch, config.train.epochs):
        torch.manual_seed(derive_seed(config.train.seed, "dropout", epoch))
        train_set.set_epoch(epoch)
        model.train()
        t0 = time.perf_counter()
        total, seen = 0.0, 0
        bar = tqdm(total=n_train, desc=f"epoch {epoch + 1}/{config.train.epochs}", unit="chunk", disable=not progress, leave=False)
        for traj, cloud, label in _loader(train_set, config.train.batch_size):
            loss = torch.nn.functional.cross_entropy(model(traj, cloud), label, weight=weight)
            require_finite_loss(loss, f"epoch {epoch + 1}, chunk {seen + len(label)} of {n_train}", last_path)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += loss.item() * len(label)
            seen += len(label)
            bar.update(len(label))
            bar.set_postfix(loss=f"{total / seen:.4f}")
        bar.close()
        p_tr, y_tr, loss_tr = predict(model, train_eval_set, weight=weight)
        p_va, y_va, loss_va = predict(model, val_set, weight=weight)
        row = {"epoch": epoch + 1, "train_loss": loss_tr, "val_loss": loss_va, "seconds": time.perf_counter() - t0}
        row.update({f"train_{k}": v for k, v in classification_report(p_tr, y_tr, config.train.ece_bins).items()})
        row.update({f"val_{k}": v for k, v in classification_report(p_va, y_va, config.train.ece_bins).items()})
        history.append(row)
        score = loss_va if config.train.select_metric == "val_loss" else -row["val_auroc"]
        improved = not math.isnan(score) and score < best_score
        if improved:
            best_score = score
        extra = {"fingerprint": fingerprint, "optimizer": optimizer.state_dict(), "epoch": epoch, "history": _untimed(history), "best_score": best_score, "split": {"train": split.train, "val": split.val}}
        ckpt = dict(config=config, model=model, action_normalizer=action_norm, cloud_normalizer=cloud_norm)
        if improved:
            save_predictor(best_path, **ckpt, extra=extra)
        save_predictor(last_path, **ckpt, extra=extra)
        write_json_atomic(out / "history.json", history)
        logger.log(epoch + 1, {**{k: v for k, v in row.items() if k != "epoch"}, "lr": optimizer.param_groups[0]["lr"]})
        if progress:
            print(
                f"epoch {epoch + 1}/{config.train.epochs}  loss {loss_tr:.4f}/{loss_va:.4f}  "
                f"acc {row['train_accuracy']:.3f}/{row['val_accuracy']:.3f}  auroc {row['val_auroc']:.3f}  "
                f"ece {row['val_ece']:.3f}  ({row['seconds']:.1f}s){'  *' if improved else ''}",
                flush=True,
            )
    logger.close()
    best = min(history, key=lambda r: r["val_loss"] if config.train.select_metric == "val_loss" else -r["val_auroc"]) if history else {}
    summary = {"run_dir": str(out), "best_checkpoint": str(best_path), "last_checkpoint": str(last_path), "best_epoch": best}
    if "val_p_spill_std" in best:  # rows of runs from before the spread was logged have none
        summary["degenerate"] = degenerate_reason(best["val_auroc"], best["val_p_spill_std"])
    return summary


STRATA = ("food", "shape")  # the index column predict_chunks copies to each chunk, the first one present


def scoring_label(label: str | None, trained_on: str) -> str:
    """The label to score against: `label`, else the one the predictor trained on; InputError for another name."""
    chosen = trained_on if label is None else label
    if chosen not in LABELS:
        raise InputError(f"--label must be one of {', '.join(LABELS)}. Got {chosen!r}.")
    return chosen


def predict_chunks(predictor: TrainedPredictor, dataset_dir: str | Path, files: list[str] | None = None,
                   label: str | None = None) -> tuple[pd.DataFrame, float]:
    """P(spill) of a trained predictor for every chunk of a spillage dataset, and the mean cross-entropy.

    One row per chunk: `episode` (the episode file, the unit a paired bootstrap resamples),
    `chunk` (its index within the episode), `food` or `shape` (the episode's, from the dataset's
    index: a rollout set's food, a spillage set's shape; the strata of the within-food AUROC), `label` (of the kind `label` names: "chunk" or
    "horizon"; default the one the predictor trained on) and `p_spill`. The order and the point
    subsets are fixed by the predictor's seed, so two calls give the same frame.
    """
    dataset_dir = Path(dataset_dir)
    cfg = predictor.config
    label = scoring_label(label, cfg.data.label)
    index = check_spillage_dataset(dataset_dir, cfg.model.n_action_steps, key="the predictor's model.n_action_steps",
                                   label=label, label_key="--label")
    dataset = SpillageChunkDataset(
        dataset_dir,
        sorted(index["file"].tolist()) if files is None else list(files),
        cloud_key=CLOUD_KEYS[cfg.data.cloud_source],
        n_action_steps=cfg.model.n_action_steps,
        action_normalizer=predictor.action_normalizer,
        cloud_normalizer=predictor.cloud_normalizer,
        points_per_object=cfg.data.points_per_object,
        shuffle=False,
        seed=cfg.train.seed,
        cache=False,
        label_key=LABEL_ARRAYS[label],
    )
    p, y, loss = predict(predictor.model, dataset)
    episodes = pd.Series(dataset.sample_episodes(), dtype=str)
    frame = pd.DataFrame({
        "episode": episodes,
        "chunk": episodes.groupby(episodes, sort=False).cumcount().astype(np.int32),
        "label": y.astype(np.int8),
        "p_spill": p,
    })
    for column in STRATA:  # what a chunk's episode is of: a rollout's food, a spillage trial's shape
        if column in index.columns:
            frame.insert(2, column, episodes.map(dict(zip(index["file"].astype(str), index[column].astype(str)))).to_numpy())
            break
    return frame, loss


def evaluate_predictor(predictor: TrainedPredictor, dataset_dir: str | Path, files: list[str] | None = None, n_bins: int = 10,
                       label: str | None = None) -> dict[str, Any]:
    """Accuracy, AUROC, ECE and loss of a trained predictor on every chunk of a (held-out) spillage
    dataset, against `label` (default: the one it trained on)."""
    label = scoring_label(label, predictor.config.data.label)
    frame, loss = predict_chunks(predictor, dataset_dir, files, label)
    return {"dataset": str(dataset_dir), "label": label, "trained_on": predictor.config.data.label, "loss": loss,
            "episodes": int(frame["episode"].nunique()), "episodes_spilling": int(frame.groupby("episode")["label"].max().sum()),
            "mean_p_spill": float(frame["p_spill"].mean()) if len(frame) else float("nan"),
            **classification_report(frame["p_spill"].to_numpy(), frame["label"].to_numpy(), n_bins)}
