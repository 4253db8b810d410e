"""The report's first screen: DP against GRITS on task success, spillage and scoop failure, with counts."""

from __future__ import annotations

import pandas as pd

from grits_lab.intervals import format_percent
from grits_lab.records import OUTCOME_COLUMNS
from grits_lab.report.tables import ReportTable, variants_of
from grits_lab.report.vocabulary import MISSING, OUTCOME_NAMES, PER_FOOD_METHODS, SIM_LABEL, method_display


def _cell(k: int, n: int) -> str:
    return f"{format_percent(k / n)} ({k}/{n})" if n else MISSING


def headline_table(episodes: pd.DataFrame | None, methods: tuple[str, ...] = PER_FOOD_METHODS) -> ReportTable:
    """One row per recorded (rho, s) variant of `methods` (default DP, GRITS): episodes and each outcome as "rate (k/n)".

    `data` holds the counts (`<outcome>_k`, `episodes`). A method without records gets a row of "—".
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
                k = int(rows[outcome].sum()) if n else 0
                row[OUTCOME_NAMES[outcome]] = _cell(k, n)
                numbers[f"{outcome}_k"] = k if n else None
            shown.append(row)
            data.append(numbers)
    return ReportTable("headline", f"Diffusion Policy vs GRITS ({SIM_LABEL})",
                       "Every recorded episode of each method, rate (episodes with the outcome / episodes); "
                       "the methods see the same seeds. Intervals and the paper's numbers: Fig. 5 below.",
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
