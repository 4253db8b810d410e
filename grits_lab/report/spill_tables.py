"""Where food is lost: spilled particles by stage and cause, and how much of a lifted load reaches the target bowl.

Both tables read the per-episode attribution columns `spilled_<stage>_<cause>` that `grits-lab
evaluate` records (grits_lab/sim/spill_metrics.py, `SpillTracker`); records made before those
columns existed give an empty table, never zeros.
"""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from grits_lab.intervals import format_rate, rate
from grits_lab.records import LOAD_ACCOUNT
from grits_lab.report.tables import ReportTable, all_variants, attribution_counts, spilled_in
from grits_lab.report.vocabulary import LEVEL_ORDER, food_display
from grits_lab.sim.spill_metrics import SPILL_CAUSES, SPILL_STAGES, attribution_columns, stage_columns

CAUSE_NAMES = {
    "over_rim": "Over the source rim",
    "off_spoon": "Off the moving spoon",
    "poured_outside": "Poured outside the target",
    "bounced_out": "Bounced out of the target",
    "posture_flip": "Thrown by a posture change",
}
STAGE_NAMES = {"scoop": "Scoop", "lift": "Lift", "carry": "Carry", "pour": "Pour", "after_pour": "After the pour"}
AFTER_SCOOP = SPILL_STAGES[1:]
# The stages whose losses the scoop causes: the scoop itself, and the lift and carry of the load it left
# (a heap above the rim sheds there); the pour and after it are the task's scripted delivery.
BEFORE_POUR = ("scoop", "lift", "carry")
# Delivered: at least this share of the lifted load ends in the target bowl, nothing spilled after the scoop.
DELIVERED_SHARE = 0.9


def has_attribution(rows: pd.DataFrame) -> bool:
    return all(c in rows.columns for c in attribution_columns())


def spilled_after_scoop(rows: pd.DataFrame) -> pd.Series:
    """(episodes,) particles spilled in the lift, carry, pour or after it."""
    return spilled_in(rows, AFTER_SCOOP)


def spilled_before_pour(rows: pd.DataFrame) -> pd.Series:
    """(episodes,) particles spilled in the scoop, lift or carry (BEFORE_POUR): the spills the scoop and the
    load it left cause, apart from what the scripted pour loses (docs/report.md)."""
    return spilled_in(rows, BEFORE_POUR)


def lifted_episodes(rows: pd.DataFrame) -> pd.DataFrame:
    """The episodes that lifted food (`scooped` > 0) and ended without an error."""
    return rows[~rows["is_error"] & (pd.to_numeric(rows["scooped"], errors="coerce") > 0)]


def delivered_share(rows: pd.DataFrame) -> tuple[pd.Series, pd.Series]:
    """(share of the lifted particles in the target bowl, delivered: at least DELIVERED_SHARE of
    them and nothing spilled after the scoop), per episode of `rows` (`lifted_episodes`)."""
    share = pd.to_numeric(rows["transferred"], errors="coerce") / pd.to_numeric(rows["scooped"], errors="coerce")
    return share, (share >= DELIVERED_SHARE) & (spilled_after_scoop(rows) == 0)


def spill_attribution_table(episodes: pd.DataFrame | None) -> ReportTable:
    """Method x stage rows, one column per cause: "episodes with that spill / particles".

    Only stages with a spill are shown; `data` holds one row per method, stage and cause with
    `episodes_k` (episodes with at least one such particle), `episodes`, and `particles`.
    """
    display_rows, data_rows = [], []
    usable = episodes is not None and not episodes.empty and has_attribution(episodes)
    for variant, name in all_variants(episodes) if usable else []:
        rows = episodes[episodes["variant"] == variant]
        counts = attribution_counts(rows)
        n = len(rows)
        for stage in SPILL_STAGES:
            cells: dict[str, str] = {}
            for cause in SPILL_CAUSES:
                column = f"spilled_{stage}_{cause}"
                k, particles = int((counts[column] > 0).sum()), int(counts[column].sum())
                data_rows.append({"method": rows["method"].iloc[0], "variant": variant, "method_name": name, "stage": stage,
                                  "cause": cause, "episodes_k": k, "episodes": n, "particles": particles})
                cells[CAUSE_NAMES[cause]] = f"{k}/{n} ({particles})" if k else "0"
            columns = stage_columns(stage)
            if counts[columns].to_numpy().sum() > 0:
                display_rows.append({"Method": name, "Stage": STAGE_NAMES[stage], **cells,
                                     "Any cause": f"{int((counts[columns].sum(axis=1) > 0).sum())}/{n}"})
    notes = [
        "Each cell: episodes with at least one particle lost that way / episodes (particles in all). A particle "
        "counts once, in the stage it was first found outside every container and not in the target bowl.",
        "Causes: over the source rim (it lay in the source bowl); off the moving spoon; poured outside the target "
        "(left the spoon in the pour or after it); bounced out of the target (it lay in the target bowl); thrown by "
        "a posture change (left the spoon within 3 actions of one whose joint step exceeded the Panda's velocity "
        "limit). docs/evaluation.md, \"Where food is lost\".",
    ]
    if episodes is not None and not episodes.empty and not usable:
        notes.insert(0, "These records predate the per-stage attribution (`spilled_<stage>_<cause>` columns).")
    elif usable and not display_rows:
        notes.insert(0, "No particle was spilled in any episode.")
    return ReportTable("spill_attribution", "Where food was lost: stage and cause of every spilled particle",
                       "Per method and stage, the episodes (and particles) lost to each cause.",
                       pd.DataFrame(display_rows), pd.DataFrame(data_rows), notes)


def delivery_table(episodes: pd.DataFrame | None) -> ReportTable:
    """How much of the lifted load reached the target bowl, per method (and per food and level for a
    run of one method, such as the oracle, experiments/oracle_transfer.yaml).

    Over episodes that lifted food (`scooped` > 0, no error): delivered = at least DELIVERED_SHARE of
    the lifted particles in the target bowl and none spilled after the scoop (Wilson 95 % interval);
    the mean share delivered; episodes with a spill after the scoop; and the mean heap above the
    spoon's rim when the scoop ended (`above_spoon_rim`).
    """
    display_rows, data_rows = [], []
    usable = (episodes is not None and not episodes.empty and has_attribution(episodes)
              and {"scooped", "transferred"} <= set(episodes.columns))
    variants = all_variants(episodes) if usable else []
    for variant, name in variants:
        rows = lifted_episodes(episodes[episodes["variant"] == variant])
        groups = [("All foods", "", rows)]
        if len(variants) == 1:
            for (food, level), g in sorted(rows.groupby(["food", "level"]),
                                           key=lambda kv: (food_display(kv[0][0]), LEVEL_ORDER.index(kv[0][1]) if kv[0][1] in LEVEL_ORDER else 9)):
                groups.append((food_display(food, long=True), level, g))
        for food, level, g in groups:
            scooped = pd.to_numeric(g["scooped"], errors="coerce")
            share, delivered = delivered_share(g)
            after = spilled_after_scoop(g)
            r = rate(int(delivered.sum()), len(g))
            heap = pd.to_numeric(g["above_spoon_rim"], errors="coerce") if "above_spoon_rim" in g.columns else None
            # Only where every episode of the group has the account: a partial sum would look whole.
            account = ({c: int(pd.to_numeric(g[c], errors="coerce").sum()) for c in LOAD_ACCOUNT}
                       if set(LOAD_ACCOUNT) <= set(g.columns) and len(g)
                       and pd.to_numeric(g[list(LOAD_ACCOUNT)].stack(future_stack=True), errors="coerce").notna().all() else None)
            display_rows.append({"Method": name, "Food": food, "Level": level, "Episodes": str(len(g)),
                                 f"Delivered (>= {DELIVERED_SHARE:.0%}, no spill)": format_rate(r),
                                 "Mean share delivered": f"{share.mean():.0%}" if len(g) else "—",
                                 "Spill after the scoop": f"{int((after > 0).sum())}/{len(g)}",
                                 "Mean lifted / above the rim": f"{scooped.mean():.1f} / {heap.mean():.1f}" if len(g) and heap is not None else "—",
                                 "Lifted: delivered / in spoon / in source / spilled / elsewhere":
                                     " / ".join(str(account[c]) for c in LOAD_ACCOUNT) if account is not None else "—"})
            data_rows.append({"method": g["method"].iloc[0] if len(g) else "", "variant": variant, "method_name": name, "food": food,
                              "level": level, "episodes": len(g), "delivered_k": int(delivered.sum()),
                              "delivered_low": r.low, "delivered_high": r.high,
                              "mean_share_delivered": float(share.mean()) if len(g) else math.nan,
                              "spill_after_scoop_k": int((after > 0).sum()),
                              "mean_scooped": float(scooped.mean()) if len(g) else math.nan,
                              "mean_above_spoon_rim": float(heap.mean()) if len(g) and heap is not None else math.nan,
                              **{c: account[c] if account is not None else math.nan for c in LOAD_ACCOUNT}})
    notes = [f"Episodes that lifted food (`scooped` > 0). Delivered: at least {DELIVERED_SHARE:.0%} of the lifted particles "
             "ended in the target bowl and none was spilled after the scoop (Wilson 95 % interval). A share above 100 % "
             "means food that was in the spoon below the source rim when the scoop was judged also arrived.",
             "Mean lifted / above the rim: particles lifted, and those of them above the spoon's rim (the heap a carry can shed).",
             "Lifted: where the lifted particles were at the episode's end, summed over its episodes: in the target bowl, "
             "still in the spoon after the pour, back in the source bowl, counted spilled, elsewhere (on a rim, say); "
             "each particle once (records' lifted_* columns, docs/evaluation.md)."]
    return ReportTable("delivery", "Delivery after the scoop: how much of the lifted load reached the target bowl",
                       "Per method over the episodes that lifted food; per food and level for a run of one method.",
                       pd.DataFrame(display_rows), pd.DataFrame(data_rows), notes)


def load_loss_figure(episodes: pd.DataFrame, path: Path) -> Path | None:
    """Scatter of what each episode lost after the scoop against the heap its scoop left above the
    spoon's rim (`above_spoon_rim`), one colour per stage that lost it (grey: nothing lost), one
    panel per method; None when the records lack the columns. Answers whether a carry sheds only
    heaped loads (a real spoon's behaviour) or level ones too (a simulation artefact)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from grits_lab.io import atomic_path

    if episodes is None or episodes.empty or not has_attribution(episodes) or "above_spoon_rim" not in episodes.columns:
        return None
    variants = all_variants(episodes)
    fig, axes = plt.subplots(1, len(variants), figsize=(min(4.2 * len(variants), 12.5), 3.4), squeeze=False, sharey=True)
    colours = {"lift": "tab:orange", "carry": "tab:red", "pour": "tab:purple", "after_pour": "tab:brown"}
    for ax, (variant, name) in zip(axes[0], variants):
        rows = lifted_episodes(episodes[episodes["variant"] == variant])
        counts = attribution_counts(rows)
        heap = pd.to_numeric(rows["above_spoon_rim"], errors="coerce").to_numpy()
        lost = spilled_after_scoop(rows).to_numpy()
        ax.scatter(heap[lost == 0], lost[lost == 0], s=14, color="0.65", label="nothing lost")
        for stage, colour in colours.items():
            by_stage = counts[stage_columns(stage)].sum(axis=1).to_numpy()
            if (by_stage > 0).any():
                ax.scatter(heap[by_stage > 0], by_stage[by_stage > 0], s=18, color=colour, label=STAGE_NAMES[stage])
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("particles above the spoon's rim after the scoop")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("particles lost after the scoop")
    axes[0][-1].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return path
