"""The one metric logger: CSV rows per step, a resumed run continues its file, curves drawn on close."""

from __future__ import annotations

import pandas as pd
import pytest

from grits_lab.training import MetricLogger
from grits_lab.training.metrics_log import TrackingConfig
from grits_lab.training.curves import curve_panels


def test_close_draws_loss_learning_rate_and_validation_panels(tmp_path):
    logger = MetricLogger(tmp_path, namespace="policy", tensorboard=False)
    for step in range(1, 6):
        logger.log(step, {"train_loss": 1.0 / step, "lr": 1e-3, "steps_per_s": 9.0})
    logger.log(6, {"train_loss": 0.1, "lr": 1e-3, "val_loss": 0.2, "val_auroc": 0.74})
    png = logger.close()
    assert png == tmp_path / "curves.png" and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    frame = pd.read_csv(tmp_path / "metrics.csv")
    assert curve_panels(frame) == [("loss", ["train_loss", "val_loss"]), ("learning rate", ["lr"]),
                                   ("validation and rollout metrics", ["val_auroc"])]


def test_a_resumed_run_drops_the_steps_after_its_checkpoint(tmp_path):
    first = MetricLogger(tmp_path, namespace="policy", tensorboard=False)
    for step in (1, 2, 3):
        first.log(step, {"train_loss": float(step)})
    first.close()
    resumed = MetricLogger(tmp_path, namespace="policy", resume_step=2, tensorboard=False)
    resumed.log(3, {"train_loss": 30.0})
    resumed.close()
    frame = pd.read_csv(tmp_path / "metrics.csv")
    assert list(frame["step"]) == [1, 2, 3] and frame["train_loss"].iloc[-1] == 30.0


def test_nothing_logged_draws_nothing(tmp_path):
    assert MetricLogger(tmp_path, namespace="policy", tensorboard=False).close() is None and not (tmp_path / "curves.png").exists()


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


def test_tensorboard_tags_are_namespaced_by_what_trains(tmp_path):
    pytest.importorskip("tensorboard", reason="the tensorboard extra: pip install -e '.[tensorboard]'")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    for namespace, values in (("policy", {"train_loss": 1.0}), ("predictor", {"train_loss": 0.25, "val_auroc": 0.5})):
        logger = MetricLogger(tmp_path / namespace, namespace=namespace)
        for step in (1, 2):
            logger.log(step, {k: v / step for k, v in values.items()})
        logger.close()
    policy = EventAccumulator(str(tmp_path / "policy" / "tensorboard"))
    predictor = EventAccumulator(str(tmp_path / "predictor" / "tensorboard"))
    policy.Reload(), predictor.Reload()
    assert policy.Tags()["scalars"] == ["policy/train_loss"]
    assert sorted(predictor.Tags()["scalars"]) == ["predictor/train_loss", "predictor/val_auroc"]
    assert [(e.step, e.value) for e in policy.Scalars("policy/train_loss")] == [(1, 1.0), (2, 0.5)]
    assert [(e.step, e.value) for e in predictor.Scalars("predictor/val_auroc")] == [(1, 0.5), (2, 0.25)]
    # the CSV, which the curves and the report read, keeps the plain names
    assert list(pd.read_csv(tmp_path / "predictor" / "metrics.csv").columns) == ["step", "train_loss", "val_auroc"]


def test_an_mlflow_store_in_the_run_directory_shows_the_run_and_a_resumed_run_continues_it(tmp_path):
    pytest.importorskip("mlflow", reason="the mlflow extra: pip install -e '.[mlflow]'")
    from mlflow.tracking import MlflowClient

    tracking = TrackingConfig(tracker="mlflow", experiment="scoop")
    first = MetricLogger(tmp_path, namespace="predictor", tracking=tracking, params={"train": {"lr": 0.001, "epochs": 3}})
    for epoch in (1, 2):
        first.log(epoch, {"train_loss": 1.0 / epoch, "val_auroc": 0.6 + 0.1 * epoch})
    first.close()
    resumed = MetricLogger(tmp_path, namespace="predictor", resume_step=2, tracking=tracking, params={"train": {"lr": 0.001}})
    resumed.log(3, {"train_loss": 0.2, "val_auroc": float("nan")})  # a metric not computed this epoch is left out
    resumed.close()
    client = MlflowClient(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    (run,) = client.search_runs([client.get_experiment_by_name("scoop").experiment_id])
    assert run.info.status == "FINISHED" and run.data.tags["grits_lab.trains"] == "predictor"
    assert run.data.params == {"train.lr": "0.001", "train.epochs": "3"}
    history = client.get_metric_history(run.info.run_id, "predictor/train_loss")
    assert [(m.step, m.value) for m in sorted(history, key=lambda m: m.step)] == [(1, 1.0), (2, 0.5), (3, 0.2)]
    assert [m.step for m in client.get_metric_history(run.info.run_id, "predictor/val_auroc")] == [1, 2]


def test_a_tracker_that_is_not_installed_is_refused_at_load(monkeypatch):
    import importlib.util

    from grits_lab.config import config_from_dict
    from grits_lab.errors import ConfigError
    from grits_lab.spillage.predictor_config import PredictorConfig

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "mlflow" else real(name, *a))
    with pytest.raises(ConfigError, match=r"`train.tracking.tracker` must be a tracker that is installed"):
        config_from_dict(PredictorConfig, {"train": {"tracking": {"tracker": "mlflow"}}})
    with pytest.raises(ConfigError, match=r"`train.tracking.tracker` must be one of"):
        config_from_dict(PredictorConfig, {"train": {"tracking": {"tracker": "wandb"}}})
