"""Two evaluation runs on the same seeds, episode by episode: which scoops stayed the same, which
outcomes changed and in which direction (`grits-lab compare-runs BEFORE AFTER`).

Episodes are paired by method, food, level and trial, and a pair must share its seed. For every
method the table gives the paired episodes, how many scoops are equal (every column of
`SCOOP_COLUMNS` equal), and for each outcome of `PAIRED_OUTCOMES` its count in each run, the
episodes where only one run had it, and the exact two-sided sign test (McNemar's exact test) on
those discordant pairs.

`compare_methods` pairs the methods of one run the same way: every method against a reference
method (Diffusion Policy) on the episodes both ran, and a method recorded at several guidance settings
or guides once more against its reference setting (`setting_reference`), the report's "Paired with
Diffusion Policy" (or "Paired with each other" when settings are paired too).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import pandas as pd

from grits_lab.errors import InputError
from grits_lab.intervals import sign_test_p
from grits_lab.io import ensure_writable_dir, write_text_atomic
from grits_lab.markdown import markdown_table
from grits_lab.records import CPU_KERNELS
from grits_lab.report.run_records import load_run
from grits_lab.report.spill_tables import (delivered_share, has_attribution, lifted_episodes, spilled_after_scoop,
                                           spilled_before_pour)
from grits_lab.report.tables import ReportTable
from grits_lab.report.vocabulary import PAPER_DEFAULTS, at_paper_defaults, method_display

PAIR_KEYS = ("method", "food", "level", "trial")
OFFSET_COLUMN = "scoop_action_offset_m"  # a scoop hook's nudge of the run (NO_HOOK_COLUMNS, grits_lab/policies/control.py)
DRAW_COLUMN = "scoop_action_offset_draw"  # which seeded directions the nudge took
# The outcomes whose AUROC ceiling a comparison table may hold (`<outcome>_auroc_ceiling` columns,
# added by a `per_method` callable such as studies/outcome_sensitivity's; comparison_markdown shows them).
CEILING_OUTCOMES = ("spillage", "spill_before_pour", "task_success")
COMPARISON_FILE = "comparison.csv"
PAIRED_METHODS_FILE = "paired.csv"
PAIR_REFERENCE = "dp"  # the unguided policy every guided variant is compared with
# What the scoop ended with: equal in both runs means the scoop was not changed.
SCOOP_COLUMNS = ("scooped", "spilled", "scoop_success", "scoop_steps")
# Outcome -> its name in the table. spill_after_scoop: a particle lost in the lift, carry, pour or after it;
# spill_before_pour: a particle lost in the scoop, lift or carry (what the scoop causes, spill_tables.BEFORE_POUR);
# lifted_food_delivered: food lifted and at least DELIVERED_SHARE of it in the target bowl with nothing
# spilled after the scoop (the oracle's goal, spill_tables.delivered_share).
PAIRED_OUTCOMES = {
    "task_success": "task success",
    "spillage": "spill during the scoop",
    "spill_after_scoop": "spill after the scoop",
    "spill_before_pour": "spill before the pour",
    "scoop_failure": "scoop failure",
    "lifted_food_delivered": "lifted food delivered",
}


def _episodes(run_dir: str | Path) -> pd.DataFrame:
    frame = load_run(run_dir).episodes
    if frame is None or frame.empty:
        raise InputError(f"{run_dir}: no episode records to compare")
    missing = [c for c in (*PAIR_KEYS, "seed", *SCOOP_COLUMNS) if c not in frame.columns]
    if missing:
        raise InputError(f"{run_dir}: the records lack {', '.join(missing)}, which pairing episodes needs")
    twice = frame.duplicated(list(PAIR_KEYS), keep=False)
    if twice.any():
        row = frame[twice].iloc[0]
        raise InputError(f"{run_dir}: {int(twice.sum())} records share their episode, e.g. {row['method']} {row['food']}/{row['level']} "
                         f"trial {row['trial']} (a method at several guidance settings or predictors); compare runs of one setting each")
    if not has_attribution(frame):
        raise InputError(f"{run_dir}: the records predate the per-stage spill columns (`spilled_<stage>_<cause>`); "
                         "compare runs of scoop-v4 or later")
    return with_paired_outcomes(frame)


def with_paired_outcomes(frame: pd.DataFrame) -> pd.DataFrame:
    """A copy of normalized records (`run_records.normalize_records`, with the attribution columns)
    with the outcomes `PAIRED_OUTCOMES` names that the records do not hold themselves:
    `spill_after_scoop`, `spill_before_pour` and `lifted_food_delivered` (False for an episode that
    lifted nothing or ended with an error)."""
    frame = frame.copy()
    frame["spill_after_scoop"] = spilled_after_scoop(frame) > 0
    frame["spill_before_pour"] = spilled_before_pour(frame) > 0
    lifted = frame.index.isin(lifted_episodes(frame).index)
    frame["lifted_food_delivered"] = lifted & delivered_share(frame)[1].fillna(False).astype(bool)
    return frame


def paired_episodes(before: pd.DataFrame, after: pd.DataFrame) -> pd.DataFrame:
    """One row per episode in both frames (`PAIR_KEYS`), columns suffixed `_before` / `_after`.
    InputError when no episode pairs or a pair's seeds differ (not the same protocol seeds)."""
    both = before.merge(after, on=list(PAIR_KEYS), suffixes=("_before", "_after"))
    if both.empty:
        raise InputError("the two runs share no episode (method, food, level, trial)")
    differ = both[both["seed_before"] != both["seed_after"]]
    if len(differ):
        row = differ.iloc[0]
        raise InputError(f"{len(differ)} paired episodes have different seeds, e.g. {row['method']} {row['food']}/{row['level']} "
                         f"trial {row['trial']}: {row['seed_before']} against {row['seed_after']}; compare runs of the same root seed")
    return both


def _equal(a: pd.Series, b: pd.Series) -> pd.Series:
    return (a == b) | (a.isna() & b.isna())


def compare_runs(before: pd.DataFrame, after: pd.DataFrame, *,
                 per_method: Callable[[pd.DataFrame, dict[str, Any]], dict[str, Any]] | None = None) -> pd.DataFrame:
    """Per method (one row each, in `before`'s order): paired episodes, equal scoops, and for every
    outcome of `PAIRED_OUTCOMES` the columns `<outcome>_before`, `_after` (episodes with it),
    `_only_before`, `_only_after` and `_p` (`sign_test_p`). Episodes with an error in either run
    are left out (`errors` counts them). `per_method(pairs, row)`, where given, returns more columns of
    a method's row from its paired episodes without errors (columns suffixed `_before` / `_after`) and
    the row so far: a study's analysis (studies/outcome_sensitivity: the AUROC ceiling)."""
    # records from before these columns ran without an offset and do not name their kernels; both sides
    # hold every column, so the merge suffixes it
    missing = {OFFSET_COLUMN: 0.0, DRAW_COLUMN: 0, CPU_KERNELS: None}
    before, after = (f.assign(**{c: v for c, v in missing.items() if c not in f.columns}) for f in (before, after))
    both = paired_episodes(before, after)
    rows = []
    for method in dict.fromkeys(both["method"]):
        pairs = both[both["method"] == method]
        errors = pairs["is_error_before"] | pairs["is_error_after"]
        pairs = pairs[~errors]
        same = pd.Series(True, index=pairs.index)
        for column in SCOOP_COLUMNS:  # two runs' records always hold them (_episodes); a run's own methods may lack some
            if f"{column}_before" in pairs.columns:
                same &= _equal(pairs[f"{column}_before"], pairs[f"{column}_after"])
        row = {"method": method, "paired": int(len(pairs)), "errors": int(errors.sum()), "scoop_equal": int(same.sum())}
        for side in ("before", "after"):
            row[f"action_offset_{side}_m"] = float(pairs[f"{OFFSET_COLUMN}_{side}"].fillna(0.0).max()) if len(pairs) else 0.0
            row[f"action_offset_draw_{side}"] = int(pairs[f"{DRAW_COLUMN}_{side}"].fillna(0).max()) if len(pairs) else 0
            labels = pairs[f"{CPU_KERNELS}_{side}"].dropna().astype(str)
            row[f"cpu_kernels_{side}"] = labels.mode().iloc[0] if len(labels) else ""
            row[f"guidance_{side}"] = _guidance_setting(pairs, side)
        kb, ka = pairs[f"{CPU_KERNELS}_before"], pairs[f"{CPU_KERNELS}_after"]
        row["kernels_differ"] = int((kb.notna() & ka.notna() & (kb.astype(str) != ka.astype(str))).sum())
        for outcome in PAIRED_OUTCOMES:
            a, b = pairs[f"{outcome}_before"].astype(bool), pairs[f"{outcome}_after"].astype(bool)
            row.update({f"{outcome}_before": int(a.sum()), f"{outcome}_after": int(b.sum()),
                        f"{outcome}_only_before": int((a & ~b).sum()), f"{outcome}_only_after": int((b & ~a).sum())})
            row[f"{outcome}_p"] = sign_test_p(row[f"{outcome}_only_before"], row[f"{outcome}_only_after"])
        if per_method is not None:
            row.update(per_method(pairs, row))
        rows.append(row)
    return pd.DataFrame(rows)


def setting_reference(rows: pd.DataFrame, key: str = "variant") -> str:
    """Of one method's records at several settings, the variant its other settings are paired with: the
    one at the paper's values (`PAPER_DEFAULTS`, rho 2.5 and s 30), else the lowest (rho, s), a predictor
    digest breaking ties; the same whatever order the records come in (a page's episodes.csv is sorted)."""
    columns = [c for c in ("rho", "s", "checkpoint_predictor") if c in rows.columns]
    settings = rows.drop_duplicates(key)[[key, *columns]].copy()
    settings["_paper"] = at_paper_defaults(settings["rho"], settings["s"]) if {"rho", "s"} <= set(columns) else False
    if "checkpoint_predictor" in columns:
        settings["checkpoint_predictor"] = settings["checkpoint_predictor"].astype(str)
    settings = settings.sort_values(["_paper", *columns, key], ascending=[False] + [True] * (len(columns) + 1), na_position="last")
    return str(settings[key].iloc[0])


def compare_methods(frame: pd.DataFrame, reference: str = PAIR_REFERENCE) -> pd.DataFrame:
    """Every other method of one run's normalized records (`run_records.normalize_records`) against
    `reference` on the episodes both ran (food, level, trial and seed): `compare_runs`'s columns with
    the reference as "before", plus `reference`, `reference_name` and `method_name`. A method recorded
    at several guidance settings or guides is paired once per variant (`method` then holds the variant
    key, e.g. `grits[rho=0.07, s=78]`), and each of its other variants is paired once more against its
    `setting_reference` (`reference` then holds that variant's key): tuned guidance against the paper's
    values on the same seeds. A pair that shares no episode is left out. Empty when the records lack
    the reference, the per-stage spill columns or any shared episode, or hold the reference itself at
    several settings."""
    if frame is None or frame.empty or "method" not in frame.columns or not has_attribution(frame):
        return pd.DataFrame()
    key = "variant" if "variant" in frame.columns else "method"
    if (frame["method"] != reference).all() or frame.duplicated([key, *PAIR_KEYS[1:]]).any():
        return pd.DataFrame()
    frame = with_paired_outcomes(frame)
    base = frame[frame["method"] == reference]
    if base[key].nunique() > 1:
        return pd.DataFrame()
    names = dict(zip(frame[key], frame["variant_name"] if "variant_name" in frame.columns else frame[key].map(method_display)))
    others = frame[frame["method"] != reference]
    pairs = [(str(base[key].iloc[0]), variant) for variant in dict.fromkeys(others[key])]
    for _, rows in others.groupby("method", sort=False):
        if rows[key].nunique() > 1:
            first = setting_reference(rows, key)
            pairs += [(first, variant) for variant in dict.fromkeys(rows[key]) if variant != first]
    tables = []
    for before, after in pairs:
        try:
            table = compare_runs(frame[frame[key] == before].assign(method=after), frame[frame[key] == after].assign(method=after))
        except InputError:  # no episode of this variant on the reference's seeds
            continue
        tables.append(table.assign(reference=before, reference_name=names[before]))
    if not tables:
        return pd.DataFrame()
    table = pd.concat(tables, ignore_index=True)
    table.insert(0, "reference", table.pop("reference"))
    table.insert(1, "reference_name", table.pop("reference_name"))
    table.insert(3, "method_name", table["method"].map(names))
    return table


def _held_outcomes(table: pd.DataFrame) -> list[str]:
    """The outcomes of PAIRED_OUTCOMES that `table` holds (a table written before an outcome existed lacks it)."""
    return [o for o in PAIRED_OUTCOMES if f"{o}_before" in table.columns]


def paired_cell(row: pd.Series, outcome: str) -> str:
    """"a → b (−only_before +only_after, p P)" for one outcome of one row of a paired table."""
    return (f"{row[f'{outcome}_before']} → {row[f'{outcome}_after']} "
            f"(−{row[f'{outcome}_only_before']} +{row[f'{outcome}_only_after']}, p {row[f'{outcome}_p']:.2g})")


def _method_name(row: pd.Series, column: str = "method") -> str:
    """A paired row's display name for `column` (`method` or `reference`): its `<column>_name` (a
    variant's, with its setting), else the method's (a paired.csv written before variants were paired
    has neither name)."""
    name = row.get(f"{column}_name")
    return str(name) if isinstance(name, str) and name else method_display(str(row[column]))


def paired_methods_markdown(table: pd.DataFrame, reference: str = PAIR_REFERENCE) -> tuple[list[str], list[list[str]], str]:
    """(header, rows, caption) of `compare_methods`'s table: per method, the reference's count →
    the method's on the same episodes, the discordant pairs and the sign test. With more than one
    reference (a method's settings paired with each other too) the rows name theirs."""
    outcomes = _held_outcomes(table)
    several = table["reference"].nunique() > 1
    head = ["Method"] + (["Against"] if several else []) + ["Paired episodes"] + [PAIRED_OUTCOMES[o] for o in outcomes]
    rows = [[_method_name(row)] + ([_method_name(row, "reference")] if several else []) + [str(row["paired"])]
            + [paired_cell(row, o) for o in outcomes] for _, row in table.iterrows()]
    first = "the reference" if several else _method_name(table.iloc[0], "reference")
    caption = (f"Episodes with each outcome, {first} → the method, on the episodes both ran (same food, level, trial "
               f"and seed); (−a +b): episodes that had it only with {first}, only with the method; p: exact two-sided "
               "sign test (McNemar's exact test) on those. Episodes with an error in either are left out.")
    if several:
        caption += (f" Against: {method_display(reference)} for every method, and for" if (table["reference"] == reference).any()
                    else " Against: for") + (" a method at several settings, its setting at the paper's values (rho "
                                             f"{PAPER_DEFAULTS['rho']}, s {PAPER_DEFAULTS['s']}), else its lowest rho, for the others.")
    return head, rows, caption


def paired_methods_table(episodes: pd.DataFrame | None, reference: str = PAIR_REFERENCE) -> ReportTable | None:
    """The report's paired table (`paired_section_title`), or None when `compare_methods` pairs nothing."""
    table = compare_methods(episodes, reference) if episodes is not None else pd.DataFrame()
    if table.empty:
        return None
    head, rows, caption = paired_methods_markdown(table, reference)
    return ReportTable("paired_methods", f"{paired_section_title(table)}: the same episodes, outcome by outcome",
                       caption, pd.DataFrame(rows, columns=head), table)


def paired_section_title(table: pd.DataFrame) -> str:
    """"Paired with <reference>", or "Paired with each other" when a method's settings are paired too."""
    return ("Paired with each other" if table["reference"].nunique() > 1
            else f"Paired with {_method_name(table.iloc[0], 'reference')}")


def _guidance_setting(pairs: pd.DataFrame, side: str) -> str:
    """`rho 2.5, s 30` (each setting a side's paired episodes ran at, `; `-joined); empty without guidance."""
    if f"rho_{side}" not in pairs.columns or f"s_{side}" not in pairs.columns:
        return ""
    settings = pairs[[f"rho_{side}", f"s_{side}"]].drop_duplicates()
    return "; ".join(f"rho {rho:g}, s {int(s)}" for rho, s in settings.itertuples(index=False) if not pd.isna(rho))


def comparison_markdown(table: pd.DataFrame) -> str:
    """The comparison (`compare_run_dirs`'s table, which names its runs) as a Markdown table with its caption."""
    before, after = str(table["before"].iloc[0]), str(table["after"].iloc[0])
    outcomes = _held_outcomes(table)
    head = ["Method", "Paired", "Scoop equal"] + [PAIRED_OUTCOMES[o] for o in outcomes]
    rows = [[method_display(row["method"]), str(row["paired"]), f"{row['scoop_equal']}/{row['paired']}"]
            + [paired_cell(row, o) for o in outcomes] for _, row in table.iterrows()]
    lines = [markdown_table(head, rows), ""]
    lines.append(f"Episodes with each outcome, {before} → {after}, on the same seeds; (−a +b): episodes that had it only "
                 "in the first run, only in the second; p: exact two-sided sign test on those. Scoop equal: scooped, "
                 "spilled, scoop success and scoop length all equal. Episodes with an error in either run are left out.")
    offsets = {side: float(table[f"action_offset_{side}_m"].max()) for side in ("before", "after")
               if f"action_offset_{side}_m" in table.columns}
    if any(offsets.values()):
        draws = {side: int(table[f"action_offset_draw_{side}"].max()) if f"action_offset_draw_{side}" in table.columns else 0
                 for side in ("before", "after")}
        named = {side: f"{offsets.get(side, 0.0) * 1000:g} mm" + (f" (draw {draws[side]})" if offsets.get(side) and any(draws.values()) else "")
                 for side in ("before", "after")}
        lines[-1] += (f" Scoop actions offset (`scoop_action_offset_m`): {named['before']} in {before}, "
                      f"{named['after']} in {after}: the changes are what that offset did.")
    if {"guidance_before", "guidance_after"} <= set(table.columns):
        setting = {side: table[f"guidance_{side}"].astype(object).fillna("") for side in ("before", "after")}  # empty reads back as NaN
        apart = table[setting["before"] != setting["after"]]
        for i, row in apart.iterrows():  # paired by episode, not by setting: say so
            lines[-1] += (f" {method_display(row['method'])} ran at {setting['before'][i] or 'no guidance'} in {before} and at "
                          f"{setting['after'][i] or 'no guidance'} in {after}: the changes include what that setting did.")
    differ = int(table["kernels_differ"].sum()) if "kernels_differ" in table.columns else 0
    if differ:
        first = table[table["kernels_differ"] > 0].iloc[0]
        lines[-1] += (f" {differ} of {int(table['paired'].sum())} pairs ran on other CPU kernels, e.g. `{first['cpu_kernels_before']}` "
                      f"in {before}, `{first['cpu_kernels_after']}` in {after}: kernels of another width round differently, "
                      "and the changes include what that did.")
    declared = "ceiling_declared" in table.columns and bool(table["ceiling_declared"].fillna(False).astype(bool).any())
    perturbation = " and ".join(p for p, held in (("offset", any(offsets.values())), ("kernels", differ)) if held) or (
        "difference between the runs" if declared else "offset")
    if declared and perturbation == "difference between the runs":
        lines[-1] += (" The runs are compared as two draws of one chance (`--declared`): what differs between them is "
                      "not in the records.")
    ceilings = [o for o in CEILING_OUTCOMES if f"{o}_auroc_ceiling" in table.columns]
    if ceilings:
        rows = [[method_display(row["method"]), PAIRED_OUTCOMES[o],
                 f"{(row[f'{o}_before'] + row[f'{o}_after']) / (2 * row['paired']):.0%}",
                 f"{row[f'{o}_only_before'] + row[f'{o}_only_after']}/{row['paired']}", _ceiling_cell(row, o)]
                for _, row in table.iterrows() for o in ceilings if f"{o}_auroc_ceiling" in row and not pd.isna(row[f"{o}_auroc_ceiling"])]
        lines += ["", markdown_table(["Method", "Outcome", "Rate, both runs", f"Changed by the {perturbation}", "AUROC ceiling [95 %]"], rows), "",
                  f"The {perturbation} is taken as chance the observations cannot show: each episode a coin, its two runs two tosses. "
                  "AUROC ceiling: the best any predictor of what both runs share can rank the outcome, over every coin mix "
                  "with the measured rate and changes (studies/outcome_sensitivity/ceiling.py); interval from resampling "
                  "episodes (200 resamples)."]
    return "\n".join(lines)


def _ceiling_cell(row: pd.Series, outcome: str) -> str:
    return (f"{row[f'{outcome}_auroc_ceiling']:.2f} [{row[f'{outcome}_auroc_ceiling_low']:.2f}, "
            f"{row[f'{outcome}_auroc_ceiling_high']:.2f}]")


def write_comparison(table: pd.DataFrame, markdown: str, output_dir: str | Path) -> list[Path]:
    """COMPARISON_FILE and comparison.md in `output_dir` (created), written atomically. In an
    experiment's folder the page's `comparison` block renders the CSV (grits_lab/report/results_pages.py)."""
    out = ensure_writable_dir(output_dir)
    write_text_atomic(out / COMPARISON_FILE, table.to_csv(index=False))
    write_text_atomic(out / "comparison.md", markdown + "\n")
    return [out / COMPARISON_FILE, out / "comparison.md"]


def compare_run_dirs(before: str | Path, after: str | Path, *,
                     per_method: Callable[[pd.DataFrame, dict[str, Any]], dict[str, Any]] | None = None) -> tuple[pd.DataFrame, str]:
    """`compare_runs` on the records of two run directories (`per_method` as there), and its Markdown."""
    table = compare_runs(_episodes(before), _episodes(after), per_method=per_method)
    table.insert(0, "after", Path(after).name)
    table.insert(0, "before", Path(before).name)
    return table, comparison_markdown(table)
