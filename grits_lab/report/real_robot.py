"""The table that puts real-robot trials (a lab's files and the paper's) beside the simulation."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import pandas as pd

from grits_lab.intervals import format_rate, rate
from grits_lab.records import OUTCOME_COLUMNS
from grits_lab.report.real_trials import PAPER_FILE, read_real_trials, real_counts
from grits_lab.report.tables import ReportTable, all_variants
from grits_lab.report.vocabulary import MAIN_METHODS, MISSING, OUTCOME_NAMES, SIM_LABEL, method_display, ordered


def real_robot_table(episodes: pd.DataFrame | None, real_files: Sequence[str | Path]) -> ReportTable:
    """Per method: the simulation's rows (one per variant), then each real-robot source's, then the paper's.

    Cells: rate [Wilson 95%] (k/n); a source that does not state an outcome shows "—".
    """
    sources = [read_real_trials(p) for p in real_files]
    real = real_counts(pd.concat([*sources, read_real_trials(PAPER_FILE)], ignore_index=True))
    sim_methods = [] if episodes is None else list(dict.fromkeys(v.split("[")[0] for v, _ in all_variants(episodes)))
    methods = ordered([*sim_methods, *real["method"]], MAIN_METHODS)
    display_rows, data_rows = [], []

    def add(method: str, label: str, name: str, counts: dict[str, tuple[int, int]]) -> None:
        shown = {"Method": name, "Source": label}
        data = {"method": method, "method_name": name, "source": label}
        for outcome in OUTCOME_COLUMNS:
            k, n = counts.get(outcome, (0, 0))
            r = rate(k, n)
            shown[OUTCOME_NAMES[outcome]] = format_rate(r) if n else MISSING
            data.update({f"{outcome}_k": k if n else math.nan, f"{outcome}_n": n,
                         f"{outcome}_rate": r.rate, f"{outcome}_ci_low": r.low, f"{outcome}_ci_high": r.high})
        display_rows.append(shown)
        data_rows.append(data)

    for method in methods:
        for variant, name in ([] if episodes is None else all_variants(episodes)):
            if variant.split("[")[0] == method:
                rows = episodes[episodes["variant"] == variant]
                add(method, SIM_LABEL, name, {o: (int(rows[o].sum()), len(rows)) for o in OUTCOME_COLUMNS})
        for row in real[real["method"] == method].to_dict("records"):
            label = "real robot (paper)" if row["source"] == "paper" else f"real robot ({row['source']})"
            add(method, label, method_display(method), {o: (row[f"{o}_k"], row[f"{o}_n"]) for o in OUTCOME_COLUMNS})
    return ReportTable(
        "real_robot", "Real robot beside the simulation",
        "Each method's simulated episodes, the real-robot trials given with --real, and the paper's real-robot "
        "numbers (100 trials per method, shipped as grits_lab/report/paper_real_robot.csv).",
        pd.DataFrame(display_rows), pd.DataFrame(data_rows),
        ["Cells: rate [Wilson 95% interval] (trials with the outcome / trials that state it); — where a source gives no number.",
         "Real-trial files follow the schema in grits_lab/report/real_trials.py."],
    )
