"""The one metric logger: CSV rows per step, a resumed run continues its file, curves drawn on close."""

from __future__ import annotations

import pandas as pd
import pytest

from grits_lab.training import MetricLogger
from grits_lab.training.curves import curve_panels


def test_close_draws_loss_learning_rate_and_validation_panels(tmp_path):
    logger = MetricLogger(tmp_path, tensorboard=False)
    for step in range(1, 6):
        logger.log(step, {"train_loss": 1.0 / step, "lr": 1e-3, "steps_per_s": 9.0})
    logger.log(6, {"train_loss": 0.1, "lr": 1e-3, "val_loss": 0.2, "val_auroc": 0.74})
    png = logger.close()
    assert png == tmp_path / "curves.png" and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    frame = pd.read_csv(tmp_path / "metrics.csv")
    assert curve_panels(frame) == [("loss", ["train_loss", "val_loss"]), ("learning rate", ["lr"]),
                                   ("validation and rollout metrics", ["val_auroc"])]


def test_a_resumed_run_drops_the_steps_after_its_checkpoint(tmp_path):
    first = MetricLogger(tmp_path, tensorboard=False)
    for step in (1, 2, 3):
        first.log(step, {"train_loss": float(step)})
    first.close()
    resumed = MetricLogger(tmp_path, resume_step=2, tensorboard=False)
    resumed.log(3, {"train_loss": 30.0})
    resumed.close()
    frame = pd.read_csv(tmp_path / "metrics.csv")
    assert list(frame["step"]) == [1, 2, 3] and frame["train_loss"].iloc[-1] == 30.0


def test_nothing_logged_draws_nothing(tmp_path):
    assert MetricLogger(tmp_path, tensorboard=False).close() is None and not (tmp_path / "curves.png").exists()


def test_a_sparse_validation_loss_keeps_the_log_scale_and_counts_stay_off_the_metrics_panel():
    from grits_lab.training.curves import curves_figure

    # The policy logs val_loss every tenth step; the predictor logs its validation set's size (val_n).
    frame = pd.DataFrame({"step": range(1, 21), "train_loss": [1.0 / s for s in range(1, 21)],
                          "val_loss": [0.5 / s if s % 10 == 0 else None for s in range(1, 21)],
                          "val_auroc": [0.24 + 0.025 * s for s in range(1, 21)], "val_n": [224] * 20})
    assert curve_panels(frame) == [("loss", ["train_loss", "val_loss"]), ("validation and rollout metrics", ["val_auroc"])]
    loss, metrics = curves_figure(frame).axes
    assert loss.get_yscale() == "log"
    assert metrics.get_ylim()[1] < 1.0  # the AUROC's rise fills the panel


def test_tensorboard_gets_the_same_scalars_with_the_extra_installed(tmp_path):
    pytest.importorskip("tensorboard", reason="the tensorboard extra: pip install -e '.[tensorboard]'")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    logger = MetricLogger(tmp_path)
    for step in (1, 2):
        logger.log(step, {"train_loss": 1.0 / step, "val_auroc": 0.5 + 0.1 * step})
    logger.close()
    events = EventAccumulator(str(tmp_path / "tensorboard"))
    events.Reload()
    assert [(e.step, e.value) for e in events.Scalars("train_loss")] == [(1, 1.0), (2, 0.5)]
    assert [e.step for e in events.Scalars("val_auroc")] == [1, 2]
