"""The report's first screen: what ran, DP against GRITS with Wilson intervals and counts, and whether that decides anything."""

from __future__ import annotations

import pandas as pd

from grits_lab.intervals import format_rate, rate
from grits_lab.records import OUTCOME_COLUMNS
from grits_lab.report.tables import ReportTable, variants_of
from grits_lab.report.vocabulary import MISSING, OUTCOME_NAMES, PER_FOOD_METHODS, SIM_LABEL, method_display

# What a GRITS row says when its predictor gives guidance no direction (grits_lab/spillage/classifier_metrics.py).
NOTHING_TO_ACT_ON = "guidance had nothing to act on"


def headline_table(episodes: pd.DataFrame | None, methods: tuple[str, ...] = PER_FOOD_METHODS,
                   degenerate: str | None = None) -> ReportTable:
    """One row per recorded (rho, s) variant of `methods` (default DP, GRITS): episodes and each outcome
    as "rate [Wilson 95 % interval] (k/n)".

    `data` holds the counts (`<outcome>_k`, `episodes`) and the bounds (`<outcome>_low`, `_high`). A
    method without records gets a row of "—". `degenerate`: why the run's predictor cannot steer
    (`degenerate_reason`), or None; when given, guided rows say NOTHING_TO_ACT_ON in a "Note" column.
    """
    shown, data = [], []
    for method in methods:
        variants = variants_of(episodes, method) or [(method, method_display(method))]
        for variant, name in variants:
            rows = episodes[episodes["variant"] == variant] if episodes is not None and len(episodes) else pd.DataFrame()
            n = len(rows)
            row = {"Method": name, "Episodes": str(n) if n else MISSING}
            numbers = {"method": method, "variant": variant, "method_name": name, "episodes": n}
            for outcome in OUTCOME_COLUMNS:
                r = rate(int(rows[outcome].sum()) if n else 0, n)
                row[OUTCOME_NAMES[outcome]] = format_rate(r, MISSING)
                numbers.update({f"{outcome}_k": r.k if n else None, f"{outcome}_low": r.low, f"{outcome}_high": r.high})
            if degenerate is not None:
                row["Note"] = f"{NOTHING_TO_ACT_ON} ({degenerate})" if method != "dp" else ""
            shown.append(row)
            data.append(numbers)
    return ReportTable("headline", f"Diffusion Policy vs GRITS ({SIM_LABEL})",
                       "Every recorded episode of each method: rate [Wilson 95% interval] (episodes with the outcome / "
                       "episodes); the methods see the same seeds. The paper's numbers: Fig. 5 below.",
                       pd.DataFrame(shown), pd.DataFrame(data))


def headline_sentence(table: ReportTable) -> str:
    """"GRITS spilled in 1 of 10 episodes, Diffusion Policy in 3 of 10." from a headline table (or why not)."""
    parts = []
    for row in table.data.itertuples():
        if row.episodes:
            parts.append(f"{row.method_name} spilled in "
                         f"{row.spillage_k} of {row.episodes} episodes and succeeded in {row.task_success_k}")
    if not parts:
        return "No Diffusion Policy or GRITS episodes are recorded in this run."
    return "; ".join(parts) + "."


def decision_sentence(table: ReportTable) -> str:
    """Whether the first DP and GRITS rows of a headline table decide anything, outcome by outcome:
    "decided" only where their Wilson 95 % intervals do not overlap; otherwise "undecided at n = N"."""
    data = table.data
    dp = data[(data["method"] == "dp") & (data["episodes"] > 0)]
    grits = data[(data["method"] != "dp") & (data["episodes"] > 0)]
    if dp.empty or grits.empty:
        return "Nothing is compared: this run lacks Diffusion Policy or GRITS episodes."
    a, b = dp.iloc[0], grits.iloc[0]
    n = f"{int(a['episodes'])}" if a["episodes"] == b["episodes"] else f"{int(a['episodes'])} and {int(b['episodes'])}"
    cells = []
    for outcome in OUTCOME_COLUMNS:
        apart = a[f"{outcome}_high"] < b[f"{outcome}_low"] or b[f"{outcome}_high"] < a[f"{outcome}_low"]
        lower = b["method_name"] if b[f"{outcome}_k"] / b["episodes"] < a[f"{outcome}_k"] / a["episodes"] else a["method_name"]
        cells.append(f"{OUTCOME_NAMES[outcome].lower()}: " + (f"decided, {lower} lower (Wilson 95% intervals apart)" if apart
                                                             else f"undecided at n = {n} (Wilson 95% intervals overlap)"))
    return f"{a['method_name']} against {b['method_name']}: " + "; ".join(cells) + "."


def episodes_sentence(episodes: pd.DataFrame | None) -> str:
    """Which foods (with their split), levels, trials and seeds the records hold, in one sentence."""
    if episodes is None or episodes.empty:
        return "No episodes ran."
    foods = []
    for food, rows in episodes.groupby("food", sort=False):
        split = str(rows["split"].iloc[0]) if "split" in rows.columns else ""
        foods.append(f"{food}{f' ({split})' if split and split != 'nan' else ''}")
    levels = ", ".join(dict.fromkeys(episodes["level"].astype(str)))
    seeds = pd.to_numeric(episodes["seed"], errors="coerce").dropna().astype(int) if "seed" in episodes.columns else pd.Series([], dtype=int)
    trials = sorted(pd.to_numeric(episodes["trial"], errors="coerce").dropna().astype(int).unique()) if "trial" in episodes.columns else []
    per_method = episodes.groupby("variant").size()
    counts = per_method.iloc[0] if per_method.nunique() == 1 else ", ".join(f"{v}: {n}" for v, n in per_method.items())
    errors = int(episodes["is_error"].sum()) if "is_error" in episodes.columns else 0
    return (f"Ran: foods {', '.join(foods)}; levels {levels}; trial{'s' if len(trials) != 1 else ''} "
            f"{', '.join(map(str, trials)) or MISSING}; {seeds.nunique()} episode seeds"
            + (f" ({', '.join(map(str, sorted(seeds.unique())))})" if 0 < seeds.nunique() <= 8 else "")
            + f"; {counts} episodes per method"
            + (f"; {errors} ended in an error, counted as a failed task (Errors, below)" if errors else "") + ".")
