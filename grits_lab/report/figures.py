"""PNG figures of the report: bar charts with Wilson 95% error bars, per-food stacks, heatmaps, sweep front.

Every figure is drawn from a ReportTable's numeric frame, so a plotted number is always the
number in the tables. Missing methods and foods are drawn as an explicit "n/a", never as a bar
of height zero.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from grits_lab.intervals import percent_digits  # noqa: E402
from grits_lab.io import atomic_path  # noqa: E402
from grits_lab.records import OUTCOME_COLUMNS  # noqa: E402
from grits_lab.report.sweep import SweepSummary  # noqa: E402
from grits_lab.report.tables import PER_FOOD_CATEGORIES, PER_FOOD_CATEGORY_NAMES  # noqa: E402
from grits_lab.report.vocabulary import (  # noqa: E402
    FOOD_ABBREVIATIONS,
    METHOD_NAMES,
    OUTCOME_NAMES,
    PAPER_DEFAULTS,
    PAPER_LABEL,
    SIM_LABEL,
    at_paper_defaults,
    food_display,
)

DPI = 150
_PALETTE = plt.get_cmap("tab10").colors
METHOD_COLORS = {m: _PALETTE[i] for i, m in enumerate(METHOD_NAMES)}
CATEGORY_COLORS = {
    "success": "#4c9a5a",
    "spillage": "#d1495b",
    "scoop_failure": "#edae49",
    "other_failure": "#9aa5b1",
    "error": "#3d3d3d",
}


VARIANT_HATCHES = ("", "//", "..", "xx", "\\\\")
MARKER_PT = 5  # size of the paper's diamonds (points)


# Colours no built-in method has, for a lab's own methods (`custom_methods`): tab10's one left, then
# others far from tab10's hues.
EXTRA_COLORS = (*_PALETTE[len(METHOD_COLORS):], "#222222", "#1b9e77", "#253494", "#e6ab02")


def method_color(method: str, extra_index: int = 0) -> tuple | str:
    """A built-in method's own colour; any other method the `extra_index`-th of EXTRA_COLORS (its
    place among the figure's methods without a colour of their own), so it never wears a built-in's."""
    return METHOD_COLORS.get(method, EXTRA_COLORS[extra_index % len(EXTRA_COLORS)])


def method_bars(data: pd.DataFrame, path: Path, title: str) -> Path:
    """Grouped bars: outcome groups, one bar per method, Wilson 95% error bars, paper values as diamonds."""
    return _save(method_bars_figure(data, title), path)


def method_bars_figure(data: pd.DataFrame, title: str) -> plt.Figure:
    """The figure `method_bars` saves; each bar's label above its error bar and the paper's diamond."""
    n_methods = max(len(data), 1)
    width = 0.8 / n_methods
    fig, ax = plt.subplots(figsize=(max(7.5, 1.0 + 1.1 * n_methods * len(OUTCOME_COLUMNS) * 0.45), 4.6))
    paper_drawn = False
    settings_seen: dict[str, int] = {}
    extra = [m for m in dict.fromkeys(data["method"]) if m not in METHOD_COLORS] if len(data) else []
    for i, row in enumerate(data.itertuples(index=False)):
        row = row._asdict()
        x = np.arange(len(OUTCOME_COLUMNS)) + (i - (n_methods - 1) / 2) * width
        label = f"{row['method_name']} (n={row['episodes']})" if not row["missing"] else f"{row['method_name']} (missing)"
        color = method_color(row["method"], extra.index(row["method"]) if row["method"] in extra else 0)
        # A method at several (rho, s) keeps its colour; its second, third... setting is hatched.
        seen = settings_seen.get(row["method"], 0)
        settings_seen[row["method"]] = seen + 1
        hatch = VARIANT_HATCHES[seen % len(VARIANT_HATCHES)]
        for j, outcome in enumerate(OUTCOME_COLUMNS):
            value = row[f"{outcome}_rate"]
            if math.isnan(value):
                ax.text(x[j], 1.5, "n/a", ha="center", va="bottom", fontsize=7, rotation=90, color="0.35")
                continue
            low, high = row[f"{outcome}_ci_low"], row[f"{outcome}_ci_high"]
            ax.bar(x[j], 100 * value, width * 0.92, color=color, label=label if j == 0 else None,
                   hatch=hatch, edgecolor="white" if hatch else None, linewidth=0,
                   yerr=[[100 * (value - low)], [100 * (high - value)]], capsize=2.5, error_kw={"lw": 0.9, "ecolor": "0.2"})
            paper = row.get(f"{outcome}_paper", math.nan)
            # The label sits above the error bar and above the paper's diamond (its half-height is
            # MARKER_PT / 2 points), so neither hides it, whatever the figure's scale.
            top, clearance = (high, 1.5) if math.isnan(paper) else (max(high, paper), 1.5 + MARKER_PT / 2 + 1.3)
            ax.annotate(percent_digits(value), (x[j], 100 * top), xytext=(0, clearance), textcoords="offset points",
                        ha="center", va="bottom", fontsize=6.5, annotation_clip=False)
            if not math.isnan(paper):
                ax.plot(x[j], 100 * paper, marker="D", color="black", markersize=MARKER_PT, linestyle="none",
                        markerfacecolor="white", markeredgewidth=1.3, label=PAPER_LABEL if not paper_drawn else None, zorder=5)
                paper_drawn = True
        if all(math.isnan(row[f"{o}_rate"]) for o in OUTCOME_COLUMNS):
            ax.bar(x[0], 0, width, color=color, label=label)  # keeps the missing method in the legend
    ax.set_xticks(range(len(OUTCOME_COLUMNS)), [OUTCOME_NAMES[o] for o in OUTCOME_COLUMNS])
    ax.set_ylabel(f"episodes with the outcome (%), {SIM_LABEL}")
    ax.set_ylim(0, 112)
    ax.set_title(title, fontsize=11)
    ax.grid(axis="y", alpha=0.3)
    ax.set_axisbelow(True)
    ax.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    fig.text(0.01, 0.01, "bars: simulation, error bars: Wilson 95% interval; n/a: no episodes", fontsize=7, color="0.35")
    return fig


def per_food_stacks(data: pd.DataFrame, path: Path, title: str) -> Path:
    """Paper Fig. 6: one panel per method, a stacked bar per food of mutually exclusive outcomes."""
    variants = list(dict.fromkeys(data["variant"]))
    foods = [f for f in dict.fromkeys(data["food"]) if f != "all"]
    fig, axes = plt.subplots(1, len(variants), figsize=(5.4 * len(variants), 0.42 * len(foods) + 2.0), squeeze=False)
    for ax, variant in zip(axes[0], variants):
        rows = data[data["variant"] == variant]
        y = np.arange(len(foods))[::-1]
        labels = []
        for yi, food in zip(y, foods):
            cell = rows[rows["food"] == food].set_index("category")
            n = int(cell["episodes"].iloc[0]) if len(cell) else 0
            abbreviation = cell["abbreviation"].iloc[0] if len(cell) and cell["abbreviation"].iloc[0] else food
            labels.append(f"{abbreviation} (n={n})" if n else f"{abbreviation} (n/a)")
            if n == 0:
                ax.text(50, yi, "n/a: no episodes", ha="center", va="center", fontsize=8, color="0.35")
                continue
            left = 0.0
            for category in PER_FOOD_CATEGORIES:
                k = int(cell.loc[category, "k"])
                share = 100 * k / n
                if k:
                    ax.barh(yi, share, left=left, color=CATEGORY_COLORS[category], edgecolor="white", height=0.75)
                    ax.text(left + share / 2, yi, str(k), ha="center", va="center", fontsize=7.5,
                            color="white" if category in ("spillage", "error", "success") else "black")
                left += share
        ax.set_yticks(y, labels)
        ax.set_xlim(0, 100)
        ax.set_xlabel("episodes (%), counts in the bars")
        ax.set_title(rows["method_name"].iloc[0], fontsize=10)
    handles = [plt.Rectangle((0, 0), 1, 1, color=CATEGORY_COLORS[c]) for c in PER_FOOD_CATEGORIES]
    fig.legend(handles, [PER_FOOD_CATEGORY_NAMES[c] for c in PER_FOOD_CATEGORIES], loc="lower center",
               ncol=len(PER_FOOD_CATEGORIES), fontsize=8, frameon=False, bbox_to_anchor=(0.5, 0.035))
    key = ", ".join(f"{a} {f.replace('_', ' ')}" for f, a in FOOD_ABBREVIATIONS.items())
    fig.text(0.5, 0.008, key, ha="center", fontsize=7, color="0.35")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout(rect=(0, 0.09, 1, 0.95))
    return _save(fig, path, tight=False)


def breakdown_heatmap(wide: dict[str, pd.DataFrame], variants: list[tuple[str, str]], path: Path) -> Path:
    """Rate per (food, level) x method for each outcome, annotated with k/n; missing cells hatched."""
    return _save(breakdown_heatmap_figure(wide, variants), path)


def breakdown_heatmap_figure(wide: dict[str, pd.DataFrame], variants: list[tuple[str, str]]) -> plt.Figure:
    """The figure `breakdown_heatmap` saves: one panel per outcome, stacked, methods as rows and
    (food, level) cells as columns, so no title has a neighbour beside it and the width does not
    grow with the number of methods."""
    first = next(iter(wide.values()))
    cells = [f"{food_display(f)} / {lv}" for f, lv in zip(first["food"], first["level"])]
    panel_height = 0.3 * len(variants) + 1.1
    fig, axes = plt.subplots(len(wide), 1, figsize=(2.2 + 0.42 * len(cells), len(wide) * panel_height + 0.6),
                             sharex=True, squeeze=False, layout="constrained")
    for ax, (outcome, frame) in zip(axes[:, 0], wide.items()):
        values = np.array([[frame[f"{v}_rate"].iloc[c] for c in range(len(frame))] for v, _ in variants], dtype=float)
        masked = np.ma.masked_invalid(values)
        # Light sequential maps keep the k/n text legible; green = good outcome, red = bad.
        cmap = plt.get_cmap("Greens" if outcome == "task_success" else "Reds").with_extremes(bad="white")
        ax.imshow(masked, cmap=cmap, vmin=0, vmax=1.4, aspect="auto")
        for r, (variant, _) in enumerate(variants):
            for c in range(len(frame)):
                n = int(frame[f"{variant}_n"].iloc[c])
                if n == 0:
                    ax.add_patch(plt.Rectangle((c - 0.5, r - 0.5), 1, 1, fill=False, hatch="///", edgecolor="0.7", lw=0))
                    ax.text(c, r, "—", ha="center", va="center", fontsize=7, color="0.4")
                else:
                    ax.text(c, r, f"{int(frame[f'{variant}_k'].iloc[c])}/{n}", ha="center", va="center", fontsize=6.5)
        ax.set_yticks(range(len(variants)), [name for _, name in variants], fontsize=7.5)
        ax.set_xticks(range(len(cells)), cells, rotation=50, ha="right", fontsize=7.5)
        ax.set_title(OUTCOME_NAMES[outcome], fontsize=9, loc="left")
    fig.suptitle("Per food x quantity level (cells: k/n; darker = higher rate; hatched —: no episodes)", fontsize=11)
    return fig


def sweep_front(summary: SweepSummary, path: Path) -> Path | None:
    """Two objectives: every completed trial, the Pareto front joined, the paper's default marked."""
    complete = summary.complete
    objectives = list(summary.objectives)
    if complete.empty or not objectives:
        return None
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    if len(objectives) >= 2:
        y_col, x_col = objectives[0], objectives[1]
        ax.scatter(complete[x_col], complete[y_col], s=22, color="0.6", label="completed trial")
        front = complete[complete["pareto"]].sort_values(x_col)
        ax.plot(front[x_col], front[y_col], "-o", color="#d1495b", markersize=5, label="Pareto front")
        # Trials with identical objectives share one point: list their parameters in one label.
        for (x, y), group in front.groupby([x_col, y_col], sort=False):
            text = "\n".join(_params_label(row, summary.parameters) for _, row in group.head(4).iterrows())
            if len(group) > 4:
                text += f"\n(+{len(group) - 4} more)"
            ax.annotate(text, (x, y), fontsize=6.5, xytext=(6, -4), textcoords="offset points", va="top")
        ax.set_xlabel(f"{x_col} ({summary.objectives[x_col]})")
        ax.set_ylabel(f"{y_col} ({summary.objectives[y_col]})")
    else:
        y_col = objectives[0]
        x_col = "rho" if "rho" in complete.columns else "number"
        points = ax.scatter(complete[x_col], complete[y_col], c=complete["s"] if "s" in complete.columns else None, s=24, cmap="viridis")
        if "s" in complete.columns:
            fig.colorbar(points, ax=ax, label="s")
        ax.set_xlabel(x_col)
        ax.set_ylabel(f"{y_col} ({summary.objectives[y_col]})")
    default = _paper_default(complete)
    if default is not None:
        ax.plot(default[x_col], default[y_col], marker="*", markersize=14, color="black", linestyle="none",
                label=f"paper default (rho={PAPER_DEFAULTS['rho']}, s={PAPER_DEFAULTS['s']})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5)
    ax.set_title(f"Sweep: {len(complete)} completed trials", fontsize=11)
    return _save(fig, path)


def _paper_default(complete: pd.DataFrame) -> pd.Series | None:
    if not {"rho", "s"} <= set(complete.columns):
        return None
    hit = complete[at_paper_defaults(complete["rho"], complete["s"])]
    return hit.iloc[0] if len(hit) else None


def _params_label(row: pd.Series, parameters: list[str]) -> str:
    return ", ".join(f"{p.removeprefix('params_')}={row[p]:.3g}" if isinstance(row[p], float) else f"{p.removeprefix('params_')}={row[p]}"
                     for p in parameters[:2])


def _save(fig: plt.Figure, path: Path, tight: bool = True) -> Path:
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI, bbox_inches="tight" if tight else None, format="png")
    plt.close(fig)
    return path
