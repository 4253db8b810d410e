"""What guidance did, per method: distributions of P(spill) before and after guidance and of the guidance displacement.

Read from the per-episode guidance columns of the evaluation records (grits_lab/evaluation/task_episode.py,
`summarize_guidance`): `p_spill_before` (the predictor's P(spill) of the plan's first guided
estimate, mean over the episode's plans), `p_spill_after` (after the last guided update) and
`guidance_displacement` (norm of the summed guidance updates of a plan, in normalized action
units over the whole (horizon x 9) plan, mean over the episode's plans). Only episodes with at
least one guided step are drawn; methods without guidance have none.

Records that compared every plan with the unguided sample from the same noise
(`guidance.compare_unguided`, the default) are read from those columns instead: P(spill) before
= of the unguided sample (`p_spill_unguided`), after = of the executed sample (`p_spill_guided`),
displacement = how far the executed chunk's spoon positions moved, in millimetres per waypoint
(`guidance_displacement_mm`); their per-plan lists (`plan_*`) give the share of plans in which
guidance lowered P(spill).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from grits_lab.records import plan_guidance_effect
from grits_lab.report.tables import ReportTable
from grits_lab.report.vocabulary import MAIN_METHODS, ordered

GUIDANCE_COLUMNS = ("p_spill_before", "p_spill_after", "guidance_displacement")


def guided_episodes(episodes: pd.DataFrame | None) -> pd.DataFrame:
    """Rows with guidance diagnostics (guided_steps > 0 and finite P(spill)); empty when the records have none."""
    if episodes is None or any(c not in episodes.columns for c in (*GUIDANCE_COLUMNS, "guided_steps")):
        return pd.DataFrame()
    steps = pd.to_numeric(episodes["guided_steps"], errors="coerce").fillna(0)
    rows = episodes[(steps > 0) & ~episodes["is_error"]].copy()
    for column in GUIDANCE_COLUMNS:
        rows[column] = pd.to_numeric(rows[column], errors="coerce")
    rows["displacement_unit"] = "normalized"
    if {"p_spill_unguided", "p_spill_guided", "guidance_displacement_mm"} <= set(rows.columns):
        compared = np.isfinite(pd.to_numeric(rows["p_spill_unguided"], errors="coerce"))
        for target, source in zip(GUIDANCE_COLUMNS, ("p_spill_unguided", "p_spill_guided", "guidance_displacement_mm")):
            rows.loc[compared, target] = pd.to_numeric(rows.loc[compared, source], errors="coerce")
        rows.loc[compared, "displacement_unit"] = "mm"
    return rows[np.isfinite(rows["p_spill_before"]) & np.isfinite(rows["p_spill_after"])]


def plans_lowered(part: pd.DataFrame) -> tuple[int, int]:
    """(plans whose executed sample has a lower P(spill) than the unguided one, plans compared)."""
    if "plan_p_spill_unguided" not in part.columns:
        return 0, 0
    lowered = total = 0
    for before, after in zip(part["plan_p_spill_unguided"], part["plan_p_spill_guided"]):
        if before is None or after is None or (isinstance(before, float) and np.isnan(before)):
            continue
        b, a = np.asarray(before, dtype=float), np.asarray(after, dtype=float)
        lowered += int((a < b).sum())
        total += len(b)
    return lowered, total


def plan_effect(rows: pd.DataFrame) -> dict[str, dict]:
    """Per method variant, what guidance did over all its compared plans (`guidance.compare_unguided`):
    {variant: {method_name, **records.plan_guidance_effect}}. Variants without per-plan lists are left out."""
    out: dict[str, dict] = {}
    if rows.empty:
        return out
    for variant in ordered(rows["variant"].unique(), MAIN_METHODS):
        part = rows[rows["variant"] == variant]
        if (effect := plan_guidance_effect(part)) is not None:
            out[str(variant)] = {"method_name": str(part["variant_name"].iloc[0]), **effect}
    return out


def plan_effect_line(effect: dict) -> str:
    """"GRITS: median P(spill) 0.194 -> 0.152 (-22 %) over 40 plans; the spoon moved 3.1 mm per waypoint (median)"."""
    change = effect["relative_change"]
    relative = f" ({change * 100:+.1f} %)" if np.isfinite(change) else ""
    return (f"{effect['method_name']}: median P(spill) of the unguided sample {effect['p_spill_unguided']:.3f} -> "
            f"executed {effect['p_spill_guided']:.3f}{relative} over {effect['plans']} plans; guidance moved the spoon "
            f"{effect['displacement_mm']:.1f} mm per waypoint (median)")


def guidance_table(rows: pd.DataFrame) -> ReportTable:
    """Per method variant: guided episodes, median [quartiles] of P(spill) before, after, and the displacement."""
    shown, data = [], []
    for variant in ordered(rows["variant"].unique(), MAIN_METHODS):
        part = rows[rows["variant"] == variant]
        name = str(part["variant_name"].iloc[0])
        entry = {"Method": name, "Guided episodes": str(len(part))}
        numbers = {"variant": variant, "method_name": name, "episodes": len(part)}
        for column, label in zip(GUIDANCE_COLUMNS, ("P(spill) before guidance", "P(spill) after guidance", "Displacement per plan")):
            q1, median, q3 = np.quantile(part[column].dropna(), [0.25, 0.5, 0.75]) if part[column].notna().any() else (np.nan,) * 3
            entry[label] = f"{median:.3f} [{q1:.3f}, {q3:.3f}]"
            numbers.update({f"{column}_median": median, f"{column}_q1": q1, f"{column}_q3": q3})
        lowered = int((part["p_spill_after"] < part["p_spill_before"]).sum())
        entry["Lowered P(spill)"] = f"{lowered}/{len(part)}"
        numbers["lowered"] = lowered
        plans_low, plans = plans_lowered(part)
        if plans:
            entry["Plans with lower P(spill)"] = f"{plans_low}/{plans}"
            numbers.update({"plans_lowered": plans_low, "plans": plans})
        entry["Displacement unit"] = "/".join(sorted(part["displacement_unit"].unique()))
        shown.append(entry)
        data.append(numbers)
    return ReportTable("guidance", "Guidance: P(spill) before and after, displacement",
                       "Per guided episode, the mean over its plans; cells: median [quartiles]. Before / after: P(spill) of the "
                       "unguided sample from the same noise and of the executed sample; displacement: mean distance between their "
                       "executed spoon positions, mm per waypoint (records without the comparison: first and last guided estimate, "
                       "and the norm of the summed updates in normalized action units).",
                       pd.DataFrame(shown), pd.DataFrame(data))


def guidance_by_plan_table(rows: pd.DataFrame, max_plans: int = 12) -> ReportTable:
    """Per method variant and plan index (0 = the episode's first plan): plans, median P(spill) of
    the unguided and of the executed sample, and median [90th percentile] displacement in mm per
    waypoint. Shows where in the scoop guidance acts: a predictor that keeps a late, holding chunk
    risky keeps moving the spoon, and a policy judged on whether it holds never gets to hold.
    Empty when the records carry no per-plan comparison (`guidance.compare_unguided`)."""
    columns = ("plan_p_spill_unguided", "plan_p_spill_guided", "plan_displacement_mm")
    shown, data = [], []
    if not set(columns) <= set(rows.columns):
        return ReportTable("guidance_by_plan", "Guidance by plan index", "", pd.DataFrame(), pd.DataFrame())
    for variant in ordered(rows["variant"].unique(), MAIN_METHODS):
        part = rows[rows["variant"] == variant]
        name = str(part["variant_name"].iloc[0])
        per_plan: dict[int, list[tuple[float, float, float]]] = {}
        for values in zip(*(part[c] for c in columns)):
            if any(v is None or (isinstance(v, float) and np.isnan(v)) for v in values):
                continue
            for index, triple in enumerate(zip(*(np.asarray(v, dtype=float) for v in values))):
                per_plan.setdefault(min(index, max_plans), []).append(triple)
        for index in sorted(per_plan):
            arr = np.asarray(per_plan[index])
            numbers = {"variant": variant, "method_name": name, "plan": index, "plans": len(arr),
                       "p_spill_unguided_median": float(np.median(arr[:, 0])), "p_spill_guided_median": float(np.median(arr[:, 1])),
                       "displacement_mm_median": float(np.median(arr[:, 2])), "displacement_mm_p90": float(np.quantile(arr[:, 2], 0.9))}
            data.append(numbers)
            shown.append({"Method": name, "Plan": f"{index}+" if index == max_plans else str(index), "Plans": str(len(arr)),
                          "P(spill) unguided": f"{numbers['p_spill_unguided_median']:.3f}",
                          "P(spill) executed": f"{numbers['p_spill_guided_median']:.3f}",
                          "Displacement (mm)": f"{numbers['displacement_mm_median']:.1f} [{numbers['displacement_mm_p90']:.1f}]"})
    return ReportTable("guidance_by_plan", "Guidance by plan index: where in the scoop it acts",
                       f"Plan 0 is each episode's first plan (plans {max_plans} and later pooled). Medians over the plans with that "
                       "index; displacement: median [90th percentile] distance between the executed spoon positions of the unguided "
                       "and the guided sample, mm per waypoint.", pd.DataFrame(shown), pd.DataFrame(data))


def guidance_figure(rows: pd.DataFrame, path: Path) -> Path:
    """Two panels: P(spill) before vs after per method (box + points, paired lines), and the displacement per method."""
    from grits_lab.report.figures import _save, method_color, plt

    variants = ordered(rows["variant"].unique(), MAIN_METHODS)
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [2, 1]})
    rng = np.random.default_rng(0)  # jitter only
    for i, variant in enumerate(variants):
        part = rows[rows["variant"] == variant]
        color = method_color(str(part["method"].iloc[0]), i)
        x0, x1 = 3 * i, 3 * i + 1
        left.boxplot([part["p_spill_before"], part["p_spill_after"]], positions=[x0, x1], widths=0.6, showfliers=False)
        jitter = rng.uniform(-0.12, 0.12, len(part))
        for before, after, j in zip(part["p_spill_before"], part["p_spill_after"], jitter):
            left.plot([x0 + j, x1 + j], [before, after], color=color, alpha=0.35, lw=0.8)
        left.scatter(x0 + jitter, part["p_spill_before"], color=color, s=10, zorder=3)
        left.scatter(x1 + jitter, part["p_spill_after"], color=color, s=10, zorder=3, marker="D")
        right.boxplot([part["guidance_displacement"].dropna()], positions=[i], widths=0.6, showfliers=False)
        right.scatter(i + rng.uniform(-0.12, 0.12, len(part)), part["guidance_displacement"], color=color, s=10, zorder=3)
    names = [str(rows.loc[rows["variant"] == v, "variant_name"].iloc[0]) for v in variants]
    left.set_xticks([3 * i + k for i in range(len(variants)) for k in (0, 1)],
                    [f"{n}\nbefore" if k == 0 else "after" for n in names for k in (0, 1)], fontsize=8)
    left.set_ylabel("predicted P(spill), mean over plans")
    left.set_ylim(-0.02, 1.02)
    left.set_title("P(spill) before and after guidance (lines: one episode)")
    right.set_xticks(range(len(variants)), names, fontsize=8)
    units = "/".join(sorted(rows["displacement_unit"].unique())) if "displacement_unit" in rows.columns else "normalized"
    right.set_ylabel(f"displacement per plan ({'mm per waypoint' if units == 'mm' else units})")
    right.set_title("How far guidance moved the plan")
    return _save(fig, path)



def plan_figure(plan: dict, path: Path, title: str = "") -> Path:
    """One guided plan drawn over its composite cloud: the executed chunk of the unguided sample
    (same noise, dashed) and of the guided one (solid), top view (x-y) and side view (x-z).

    plan: a `DiffusionController.captured` entry: `cloud` (3, N, 3) food / spoon / bowl points
    (world, m), `unguided` and `guided` (n_action_steps, 3) spoon positions (m), their
    `p_spill_unguided` / `p_spill_guided` and `displacement_mm`.
    """
    from grits_lab.report.figures import _save, plt

    cloud = np.asarray(plan["cloud"], dtype=float)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    for ax, (i, j, labels) in zip(axes, [(0, 1, ("x (m)", "y (m)")), (0, 2, ("x (m)", "z (m)"))]):
        for obj, (name, color, size) in enumerate([("food", "#c98b2b", 6), ("spoon", "#777777", 3), ("bowl", "#9ecae1", 2)]):
            pts = cloud[obj]
            ax.scatter(pts[:, i], pts[:, j], s=size, color=color, alpha=0.5, label=name, linewidths=0)
        for key, style, color in (("unguided", "--", "#1f77b4"), ("guided", "-", "#d62728")):
            xyz = np.asarray(plan[key], dtype=float)
            p = plan[f"p_spill_{key}"]
            ax.plot(xyz[:, i], xyz[:, j], style, color=color, lw=2, marker="o", ms=3, label=f"{key}: P(spill) {p:.3f}")
            ax.scatter(xyz[:1, i], xyz[:1, j], color=color, s=40, marker="s", zorder=4)
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        ax.set_aspect("equal", adjustable="datalim")
    axes[0].legend(fontsize=7, loc="best")
    axes[0].set_title("top view")
    axes[1].set_title("side view")
    fig.suptitle(f"{title}plan {plan['plan']}: guidance moved the executed chunk {plan['displacement_mm']:.1f} mm per waypoint", fontsize=10)
    return _save(fig, path)
