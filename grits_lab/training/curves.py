"""Training curves as one PNG per run: losses, learning rate, validation metrics, from `metrics.csv`.

Drawn by `MetricLogger.close()` beside the CSV (`curves.png`), for the policy, BC and the
predictor alike; the pipeline's report shows them in its "Training" section.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from grits_lab.io import atomic_path

CURVES_FILE = "curves.png"
# Columns drawn on their own panel, in this order, when present. A count (`val_n`, the validation
# set's size) is not a metric: drawn beside rates in [0, 1] it would flatten them.
PANELS = (
    ("loss", lambda c: c.endswith("loss")),
    ("learning rate", lambda c: c == "lr"),
    ("validation and rollout metrics",
     lambda c: (c.startswith("val_") or c.startswith("rollout_")) and not c.endswith("loss") and not c.endswith("_n")),
)


def curve_panels(frame: pd.DataFrame) -> list[tuple[str, list[str]]]:
    """(panel title, metric columns) of the panels a metrics frame fills, in PANELS order."""
    if frame.empty or "step" not in frame.columns:
        return []
    panels = [(name, [c for c in frame.columns if c != "step" and pick(c) and frame[c].notna().any()]) for name, pick in PANELS]
    return [(name, columns) for name, columns in panels if columns]


def plot_curves(metrics_csv: str | Path, png: str | Path, title: str = "") -> Path | None:
    """Write the curves of `metrics_csv` (a `step` column and one column per metric) to `png`;
    None (nothing written) when the file holds no logged step."""
    fig = curves_figure(pd.read_csv(metrics_csv), title)
    if fig is None:
        return None
    import matplotlib.pyplot as plt

    png = Path(png)
    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return png


def curves_figure(frame: pd.DataFrame, title: str = ""):
    """The matplotlib figure of `plot_curves` (one axes per panel); None when no panel is filled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = curve_panels(frame)
    if not panels:
        return None
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.2), squeeze=False, layout="constrained")
    for ax, (name, columns) in zip(axes[0], panels):
        for column in columns:
            rows = frame[["step", column]].dropna()
            ax.plot(rows["step"], rows[column], marker="o" if len(rows) <= 30 else None, markersize=3, label=column)
        if name == "loss" and frame[columns].min().min() > 0:  # NaN-free: val_loss is logged on fewer steps
            ax.set_yscale("log")
        ax.set_title(name, fontsize=9, loc="left")
        ax.set_xlabel("step", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
