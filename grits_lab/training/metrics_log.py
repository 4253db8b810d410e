"""Training logs: one metric logger for the policy, BC and the predictor.

Every logged step is a row of `metrics.csv` (readable with pandas), a scalar in TensorBoard when
it is installed (`pip install -e ".[tensorboard]"`; `tensorboard --logdir RUN_DIR/tensorboard`),
a metric of an MLflow run when `tracking.tracker: mlflow` (`pip install -e ".[mlflow]"`), and on
close the run's curves are drawn to `curves.png` (grits_lab/training/curves.py). TensorBoard tags
and MLflow keys are namespaced by what trains (`policy/train_loss`, `predictor/val_auroc`), so
runs of the policy and the predictor in one log directory or one experiment keep apart; the CSV
keeps the plain names.

The CSV is appended to, so a resumed run continues the same file; rows past the resume step
(written after the last checkpoint by the interrupted run) are dropped on reopening, so the log
never holds two values for one step. A resumed run continues its MLflow run too (its id is kept
in RUN_DIR/tracking.json); MLflow keeps what the interrupted run logged past the checkpoint, so
its history may hold two values for those steps.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from grits_lab.config import require
from grits_lab.errors import GritsError

TRACKING_FILE = "tracking.json"
MLFLOW_DB = "mlflow.db"  # the default MLflow store: a SQLite file in the run directory (MLflow 3 retired file stores)


@dataclass
class TrackingConfig:
    """An experiment tracker that shows a training run beside metrics.csv and TensorBoard.

    `tracker: mlflow` logs every step's metrics (namespaced, e.g. `policy/train_loss`) and the
    run's config (as dotted params) to the MLflow tracking store `uri`: by default a SQLite file
    in the run directory, RUN_DIR/mlflow.db, which needs no server
    (`mlflow ui --backend-store-uri sqlite:///RUN_DIR/mlflow.db`); any MLflow tracking URI works
    (`sqlite:///shared/mlflow.db` for many runs, `http://host:5000`). `experiment` names the MLflow
    experiment. Checked at load: mlflow must be importable.
    """

    tracker: Literal["none", "mlflow"] = "none"
    uri: str = ""  # MLflow tracking URI; "" = sqlite:///RUN_DIR/mlflow.db
    experiment: str = "grits_lab"

    def __post_init__(self) -> None:
        require(self.tracker == "none" or importlib.util.find_spec("mlflow") is not None, "tracking.tracker",
                self.tracker, 'a tracker that is installed (pip install -e ".[mlflow]")')
        require(bool(self.experiment), "tracking.experiment", self.experiment, "a non-empty name")


class MetricLogger:
    """`log(step, {name: value})` to metrics.csv (and TensorBoard, MLflow); `close()` draws curves.png.

    Names: `train_loss`, `val_loss`, `lr` and any `val_*` / `rollout_*` metric are drawn on the
    curves' loss, learning-rate and validation panels; a step is an optimizer step for the
    policy and BC, an epoch for the predictor. `namespace` says what trains (`policy`, `bc`,
    `predictor`): TensorBoard's tags and MLflow's keys are `namespace/name`. `params` (a config
    as a nested dict) are logged to a new MLflow run.
    """

    def __init__(self, directory: str | Path, *, namespace: str, resume_step: int = 0, tensorboard: bool = True,
                 title: str = "", tracking: TrackingConfig | None = None, params: dict[str, Any] | None = None) -> None:
        self.title = title
        self.namespace = namespace
        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self.path = self.directory / "metrics.csv"
        self.fields: list[str] = ["step"]
        rows: list[dict[str, str]] = []
        if self.path.exists():
            with open(self.path, newline="") as fh:
                reader = csv.DictReader(fh)
                self.fields = list(reader.fieldnames or ["step"])
                rows = [r for r in reader if r.get("step") and int(float(r["step"])) <= resume_step]
        self._rewrite(rows)
        self.writer = None
        if tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter

                self.writer = SummaryWriter(str(self.directory / "tensorboard"), purge_step=resume_step + 1)
            except ImportError:
                self.writer = None
        self.tracker = MlflowRun.open(self.directory, namespace, tracking, params) if tracking and tracking.tracker == "mlflow" else None

    def log(self, step: int, values: dict[str, float]) -> None:
        new = [k for k in values if k not in self.fields]
        if new:
            with open(self.path, newline="") as fh:
                rows = list(csv.DictReader(fh))
            self.fields += new
            self._rewrite(rows)
        with open(self.path, "a", newline="") as fh:
            csv.DictWriter(fh, fieldnames=self.fields).writerow({"step": step, **values})
        if self.writer is not None:
            for key, value in values.items():
                self.writer.add_scalar(f"{self.namespace}/{key}", value, step)
        if self.tracker is not None:
            self.tracker.log(step, {f"{self.namespace}/{k}": v for k, v in values.items()})

    def close(self) -> Path | None:
        """Close TensorBoard and draw the curves; returns curves.png (None: nothing logged)."""
        from grits_lab.training.curves import CURVES_FILE, plot_curves

        if self.writer is not None:
            self.writer.close()
        if self.tracker is not None:
            self.tracker.close()
        return plot_curves(self.path, self.directory / CURVES_FILE, self.title)

    def _rewrite(self, rows: list[dict[str, Any]]) -> None:
        with open(self.path, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=self.fields)
            writer.writeheader()
            writer.writerows(rows)


class MlflowRun:
    """One training run's MLflow run, through `MlflowClient` (no global active run, so runs in one
    process never share one); its id is kept in RUN_DIR/tracking.json so a resumed run continues it."""

    def __init__(self, client: Any, run_id: str) -> None:
        self.client, self.run_id = client, run_id

    @classmethod
    def open(cls, directory: Path, namespace: str, config: TrackingConfig, params: dict[str, Any] | None) -> "MlflowRun":
        from mlflow.tracking import MlflowClient

        uri = config.uri or f"sqlite:///{(directory / MLFLOW_DB).resolve()}"
        client = MlflowClient(tracking_uri=uri)
        stored = directory / TRACKING_FILE
        if stored.exists():
            kept = json.loads(stored.read_text())
            if kept.get("uri") == uri:
                client.update_run(kept["run_id"], status="RUNNING")
                return cls(client, kept["run_id"])
        experiment = client.get_experiment_by_name(config.experiment)
        experiment_id = experiment.experiment_id if experiment else client.create_experiment(config.experiment)
        run = client.create_run(experiment_id, run_name=f"{namespace} {directory.name}", tags={"grits_lab.trains": namespace})
        for key, value in sorted(_flatten(params or {}).items()):
            client.log_param(run.info.run_id, key, str(value)[:6000])  # MLflow's limit on a param's length
        from grits_lab.io import write_json_atomic

        write_json_atomic(stored, {"tracker": "mlflow", "uri": uri, "run_id": run.info.run_id, "experiment": config.experiment})
        return cls(client, run.info.run_id)

    def log(self, step: int, values: dict[str, float]) -> None:
        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        metrics = [Metric(k, float(v), now, int(step)) for k, v in values.items() if v is not None and math.isfinite(float(v))]
        if metrics:
            self.client.log_batch(self.run_id, metrics=metrics)

    def close(self) -> None:
        self.client.set_terminated(self.run_id)


def _flatten(params: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(_flatten(value, f"{name}."))
        else:
            out[name] = value
    return out


def require_finite_loss(loss: Any, where: str, checkpoint: Any = None) -> None:
    """Stop training with one line when the loss is NaN or infinite, before it reaches the weights.

    `where` says when (e.g. "step 120"); `checkpoint` is the last good checkpoint, if any.
    """
    value = float(loss.detach()) if hasattr(loss, "detach") else float(loss)
    if not math.isfinite(value):
        kept = f"; the last good checkpoint is {checkpoint}" if checkpoint is not None and Path(checkpoint).exists() else ""
        raise GritsError(f"training loss became {value} at {where}: lower the learning rate or look for "
                         f"non-finite values in the dataset{kept}")
