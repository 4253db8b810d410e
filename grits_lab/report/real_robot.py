"""The table that puts real-robot trials (a lab's files and the paper's) beside the simulation."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import pandas as pd

from grits_lab.intervals import format_rate, rate
from grits_lab.records import OUTCOME_COLUMNS
from grits_lab.report.real_trials import ALL, PAPER_FILE, PAPER_SOURCE, canonical_name, read_real_files, read_real_trials, real_counts
from grits_lab.report.tables import ReportTable, all_variants
from grits_lab.report.vocabulary import (
    MAIN_METHODS, METHOD_NAMES, MISSING, OUTCOME_NAMES, PAPER_LABEL, SIM_LABEL, method_display, ordered,
)


def real_robot_table(episodes: pd.DataFrame | None, real_files: Sequence[str | Path]) -> ReportTable:
    """Per method and real-robot source (each lab's files, then the paper's): the simulation's rows
    (one per variant) over the simulated episodes of the foods and levels of that source's trials,
    then the source's own row. A source whose trials pool every food and level (the paper's) stands
    beside every simulated episode; rows of one selection are shown once. The `selection` column
    and the notes state which episodes each row counts.

    Cells: rate [Wilson 95%] (k/n); a source that does not state an outcome shows "—". InputError
    (one line, naming the file) for a bad trials file: grits_lab/report/real_trials.py.
    """
    known = set(METHOD_NAMES) | (set() if episodes is None else set(episodes["method"]))
    sources = read_real_files(list(real_files), known)
    real = real_counts(pd.concat([*sources, read_real_trials(PAPER_FILE)], ignore_index=True))
    sim_methods = [] if episodes is None else list(dict.fromkeys(v.split("[")[0] for v, _ in all_variants(episodes)))
    methods = ordered([*sim_methods, *real["method"]], MAIN_METHODS)
    display_rows, data_rows, notes = [], [], {}

    def add(method: str, label: str, name: str, selection: str, counts: dict[str, tuple[int, int]]) -> None:
        shown = {"Method": name, "Source": label, "Episodes of": selection}
        data = {"method": method, "method_name": name, "source": label, "selection": selection}
        for outcome in OUTCOME_COLUMNS:
            k, n = counts.get(outcome, (0, 0))
            r = rate(k, n)
            shown[OUTCOME_NAMES[outcome]] = format_rate(r) if n else MISSING
            data.update({f"{outcome}_k": k if n else math.nan, f"{outcome}_n": n,
                         f"{outcome}_rate": r.rate, f"{outcome}_ci_low": r.low, f"{outcome}_ci_high": r.high})
        display_rows.append(shown)
        data_rows.append(data)

    for method in methods:
        shown_selections: set[tuple[int, ...]] = set()
        variants = [(v, n) for v, n in ([] if episodes is None else all_variants(episodes)) if v.split("[")[0] == method]
        for row in real[real["method"] == method].to_dict("records"):
            label = PAPER_LABEL if row["source"] == PAPER_SOURCE else f"real robot ({row['source']})"
            selection = describe_pairs(row["pairs"])
            if variants:
                chosen = _same_foods_and_levels(episodes, row["pairs"])
                picked = tuple(chosen.index[chosen["method"] == method])
                if picked not in shown_selections:  # the same episodes as a row above: shown once
                    shown_selections.add(picked)
                    whole = len(picked) == int((episodes["method"] == method).sum())
                    sim_label = SIM_LABEL if whole else f"{SIM_LABEL} (as {row['source']})"
                    if not whole:
                        notes[sim_label] = (f"{sim_label}: the simulated episodes of {selection}, the foods and levels "
                                            f"of the trials of {row['source']}")
                    for variant, name in variants:
                        rows = chosen[chosen["variant"] == variant]
                        add(method, sim_label, name, describe_pairs(()) if whole else selection,
                            {o: (int(rows[o].sum()), len(rows)) for o in OUTCOME_COLUMNS})
            add(method, label, method_display(method), selection, {o: (row[f"{o}_k"], row[f"{o}_n"]) for o in OUTCOME_COLUMNS})
        if not len(real[real["method"] == method]):  # simulated only
            for variant, name in variants:
                rows = episodes[episodes["variant"] == variant]
                add(method, SIM_LABEL, name, describe_pairs(()), {o: (int(rows[o].sum()), len(rows)) for o in OUTCOME_COLUMNS})
    return ReportTable(
        "real_robot", "Real robot beside the simulation",
        "Each method's simulated episodes of the foods and levels of each real-robot source's trials, the "
        "real-robot trials given with --real, and the paper's real-robot numbers (100 trials per method over "
        "its foods and levels, shipped as grits_lab/report/paper_real_robot.csv).",
        pd.DataFrame(display_rows), pd.DataFrame(data_rows),
        ["Cells: rate [Wilson 95% interval] (trials with the outcome / trials that state it); — where a source gives no number.",
         "Episodes of: the foods and levels a row counts; `simulation` rows count every simulated episode of the method.",
         *notes.values(),
         "Real-trial files follow the schema in grits_lab/report/real_trials.py."],
    )


def _same_foods_and_levels(episodes: pd.DataFrame, pairs: Sequence[tuple[str, str]]) -> pd.DataFrame:
    """The episodes whose (food, level) is one of `pairs` (`all` matches any food or level)."""
    food = episodes["food_key"] if "food_key" in episodes else episodes["food"].map(canonical_name)
    mask = pd.Series(False, index=episodes.index)
    for f, level in pairs:
        mask |= ((food == f) | (f == ALL)) & ((episodes["level"] == level) | (level == ALL))
    return episodes[mask]


def describe_pairs(pairs: Sequence[tuple[str, str]]) -> str:
    """`sago low, cereal high`; `all foods and levels` for one aggregate over both."""
    if not pairs or tuple(pairs) == ((ALL, ALL),):
        return "all foods and levels"
    return ", ".join(f"{'all foods' if f == ALL else f.replace('_', ' ')} {'all levels' if level == ALL else level}"
                     for f, level in pairs)
