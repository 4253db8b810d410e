"""Training logs: one metric logger for the policy, BC and the predictor.

Every logged step is a row of `metrics.csv` (readable with pandas), a scalar in TensorBoard when
it is installed (`pip install -e ".[tensorboard]"`; `tensorboard --logdir RUN_DIR/tensorboard`),
and on close the run's curves are drawn to `curves.png` (grits_lab/training/curves.py).

The CSV is appended to, so a resumed run continues the same file; rows past the resume step
(written after the last checkpoint by the interrupted run) are dropped on reopening, so the log
never holds two values for one step.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from grits_lab.errors import GritsError


class MetricLogger:
    """`log(step, {name: value})` to metrics.csv (and TensorBoard); `close()` draws curves.png.

    Names: `train_loss`, `val_loss`, `lr` and any `val_*` / `rollout_*` metric are drawn on the
    curves' loss, learning-rate and validation panels; a step is an optimizer step for the
    policy and BC, an epoch for the predictor.
    """

    def __init__(self, directory: str | Path, resume_step: int = 0, tensorboard: bool = True, title: str = "") -> None:
        self.title = title
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
                self.writer.add_scalar(key, value, step)

    def close(self) -> Path | None:
        """Close TensorBoard and draw the curves; returns curves.png (None: nothing logged)."""
        from grits_lab.training.curves import CURVES_FILE, plot_curves

        if self.writer is not None:
            self.writer.close()
        return plot_curves(self.path, self.directory / CURVES_FILE, self.title)

    def _rewrite(self, rows: list[dict[str, Any]]) -> None:
        with open(self.path, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=self.fields)
            writer.writeheader()
            writer.writerows(rows)


def require_finite_loss(loss: Any, where: str, checkpoint: Any = None) -> None:
    """Stop training with one line when the loss is NaN or infinite, before it reaches the weights.

    `where` says when (e.g. "step 120"); `checkpoint` is the last good checkpoint, if any.
    """
    value = float(loss.detach()) if hasattr(loss, "detach") else float(loss)
    if not math.isfinite(value):
        kept = f"; the last good checkpoint is {checkpoint}" if checkpoint is not None and Path(checkpoint).exists() else ""
        raise GritsError(f"training loss became {value} at {where}: lower the learning rate or look for "
                         f"non-finite values in the dataset{kept}")
