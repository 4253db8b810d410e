"""Sweep summary: trial states, best parameters and the Pareto front from a sweep's trials table.

Expected trials table (`grits-lab sweep`, Optuna's trials_dataframe or an equivalent): one row
per trial with the parameters `rho` and `s` (or `params_rho`, `params_s`), a `state`
(COMPLETE, FAIL, RUNNING, PRUNED...), optionally `number`, and objective columns named by what
they measure: `task_success` (maximized) and `spillage` (minimized), also accepted as
`success_rate`/`spillage_rate` or with Optuna's `user_attrs_` prefix. Unnamed objectives
`value` or `values_0`, `values_1`, ... are read with the directions given by `directions`
(or `direction`) in the best-parameters YAML; without them they are assumed maximized, and the
report says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import pandas as pd
from grits_lab.report.run_compare import PAIRED_OUTCOMES, paired_cell
from grits_lab.report.tables import ReportTable
from grits_lab.report.vocabulary import MISSING, PAPER_DEFAULTS, method_display

PARAMETERS = ("rho", "s")
# The paper's trade-off: at most one success column (maximized) and one spillage column (minimized).
NAMED_OBJECTIVES = (
    (("task_success", "success_rate", "success"), "maximize"),
    (("spillage", "spillage_rate"), "minimize"),
)
# Shown beside the objectives when the trials table has them (grits_lab/tune writes these).
CONTEXT_COLUMNS = ("scoop_failure_rate", "n_episodes", "n_errors", "feasible")
COMPLETE_STATES = {"COMPLETE", "TRIALSTATE.COMPLETE"}


@dataclass
class SweepSummary:
    trials: pd.DataFrame  # normalized: number, state, parameters, objectives, pareto
    parameters: list[str]
    objectives: dict[str, str]  # column -> "maximize" | "minimize"
    notes: list[str] = field(default_factory=list)

    @property
    def complete(self) -> pd.DataFrame:
        return self.trials[self.trials["complete"]]


def summarize_sweep(trials: pd.DataFrame, best_params: dict[str, Any] | None) -> SweepSummary:
    frame = trials.copy()
    notes = []
    for name in PARAMETERS:
        if name not in frame.columns and f"params_{name}" in frame.columns:
            frame[name] = frame[f"params_{name}"]
    parameters = [c for c in PARAMETERS if c in frame.columns]
    parameters += [c for c in frame.columns if c.startswith("params_") and c[len("params_"):] not in parameters]
    if "number" not in frame.columns:
        frame["number"] = range(len(frame))
    frame["state"] = frame["state"].astype(str) if "state" in frame.columns else "COMPLETE"
    objectives = _objectives(frame, best_params, notes)
    for column in objectives:
        frame[column] = pd.to_numeric(frame[column], errors="coerce")
    frame["complete"] = frame["state"].str.upper().isin(COMPLETE_STATES)
    if objectives:
        frame["complete"] &= frame[list(objectives)].notna().all(axis=1)
    frame["pareto"] = pareto_mask(frame, objectives) & frame["complete"]
    return SweepSummary(frame, parameters, objectives, notes)


def pareto_mask(frame: pd.DataFrame, objectives: dict[str, str]) -> pd.Series:
    """True for completed trials no other completed trial dominates (ties kept on the front)."""
    mask = pd.Series(False, index=frame.index)
    complete = frame[frame["complete"]] if "complete" in frame.columns else frame
    if complete.empty or not objectives:
        return mask
    # Flip signs so that every objective is minimized.
    signed = pd.DataFrame({c: complete[c] * (-1 if d == "maximize" else 1) for c, d in objectives.items()})
    values = signed.to_numpy()
    for i, index in enumerate(signed.index):
        dominated = ((values <= values[i]).all(axis=1) & (values < values[i]).any(axis=1)).any()
        mask.at[index] = not dominated
    return mask


def sweep_tables(summary: SweepSummary, best_params: dict[str, Any] | None, best_file: str | None) -> list[ReportTable]:
    trials = summary.trials
    states = trials["state"].value_counts()
    state_display = pd.DataFrame({"State": states.index, "Trials": states.values.astype(str)})
    tables = [ReportTable(
        "sweep_states", "Sweep: trials by state", "Trials of the sweep, by final state.",
        state_display, pd.DataFrame({"state": states.index, "trials": states.values}), list(summary.notes),
    )]
    columns = ["number", *summary.parameters, *summary.objectives]
    columns += [c for c in CONTEXT_COLUMNS if c in trials.columns and c not in columns]
    if best_params is not None:
        flat = _flatten(best_params)
        best_display = pd.DataFrame({"Parameter": list(flat), "Value": [_fmt(v) for v in flat.values()]})
        best_data = pd.DataFrame([{"source": best_file, **flat}])
    else:
        best = _best_trial(summary)
        if best is None:
            best_display = pd.DataFrame({"Best parameters": [MISSING]})
            best_data = pd.DataFrame()
        else:
            best_display = pd.DataFrame([{c: _fmt(best[c]) for c in columns}])
            best_data = pd.DataFrame([best[columns]])
    tables.append(ReportTable(
        "sweep_best", "Sweep: best parameters",
        "From the sweep's best-parameters YAML when present, otherwise the best completed trial "
        "(single objective) or the front member with the highest first objective.",
        best_display, best_data,
        [f"Source: {best_file or 'the trials table'}. Paper defaults: rho = {PAPER_DEFAULTS['rho']}, s = {PAPER_DEFAULTS['s']}."],
    ))
    front = summary.complete[summary.complete["pareto"]]
    if summary.objectives:
        front = front.sort_values(list(summary.objectives), ascending=[d == "minimize" for d in summary.objectives.values()])
    notes = [] if len(summary.objectives) >= 2 else ["A single objective has no Pareto front; the best trial is shown."]
    if front.empty:
        notes.insert(0, "Missing: no completed trials with objective values.")
    directions = ", ".join(f"{c} ({d})" for c, d in summary.objectives.items()) or MISSING
    tables.append(ReportTable(
        "sweep_pareto", "Sweep: Pareto front", f"Completed trials not dominated on {directions}.",
        pd.DataFrame([{c: _fmt(row[c]) for c in columns} for _, row in front.iterrows()], columns=columns),
        front[columns].reset_index(drop=True), notes,
    ))
    return tables


def _objectives(frame: pd.DataFrame, best_params: dict[str, Any] | None, notes: list[str]) -> dict[str, str]:
    named = {}
    for names, direction in NAMED_OBJECTIVES:
        candidates = [c for name in names for c in (name, f"user_attrs_{name}") if c in frame.columns]
        if candidates:
            named[candidates[0]] = direction
    if named:
        return named
    unnamed = [c for c in frame.columns if c == "value" or (c.startswith("values_") and c[7:].isdigit())]
    unnamed.sort(key=lambda c: int(c[7:]) if c != "value" else 0)
    given = (best_params or {}).get("directions") or (best_params or {}).get("direction")
    if isinstance(given, str):
        given = [given]
    if isinstance(given, list) and len(given) == len(unnamed) and all(d in ("maximize", "minimize") for d in given):
        return dict(zip(unnamed, given))
    if unnamed:
        notes.append("Objective directions are not recorded; all objectives are assumed maximized.")
    return {c: "maximize" for c in unnamed}


def _best_trial(summary: SweepSummary) -> pd.Series | None:
    complete = summary.complete
    if complete.empty or not summary.objectives:
        return None
    first, direction = next(iter(summary.objectives.items()))
    candidates = complete[complete["pareto"]]
    index = candidates[first].idxmax() if direction == "maximize" else candidates[first].idxmin()
    return complete.loc[index]


def _fmt(value: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return MISSING
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _flatten(mapping: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat = {}
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{name}."))
        else:
            flat[name] = value if not isinstance(value, list) else str(value)
    return flat


# reference.csv's column suffixes -> the paired tables' (run_compare), so one formatter writes both.
_REFERENCE_SUFFIXES = {"_only_reference": "_only_before", "_only_trial": "_only_after",
                       "_reference": "_before", "_trial": "_after"}


def sweep_reference_table(reference: pd.DataFrame | None, every_trial: bool = False) -> ReportTable | None:
    """The Pareto-front trials paired with each of the sweep's reference methods (`reference.csv` of
    grits_lab/tune/reference.py), or None without one. `every_trial`: every trial reference.csv pairs
    (the completed trials whose records could be read), by rho, with a Front column: where along rho
    guidance starts to cost what the reference does."""
    needed = {"reference", "trial", "rho", "s", "paired", "pareto_front"}
    if reference is None or reference.empty or not needed <= set(reference.columns):
        return None  # none, or a table of another shape: nothing said rather than a wrong pairing
    marked = reference.assign(_front=reference["pareto_front"].map(_is_true), _rho=pd.to_numeric(reference["rho"], errors="coerce"))
    shown = (marked.sort_values(["reference", "_rho", "s", "trial"]) if every_trial
             else marked[marked["_front"]].sort_values(["reference", "trial"]))
    outcomes = [o for o in (c.removesuffix("_p") for c in reference.columns if c.endswith("_p"))
                if all(f"{o}{k}" in reference.columns for k in _REFERENCE_SUFFIXES)]
    renamed = shown.rename(columns=lambda c: next((c.removesuffix(k) + v for k, v in _REFERENCE_SUFFIXES.items()
                                                   if c.endswith(k) and c.removesuffix(k) in outcomes), c))
    head = ["Reference", "Trial", "rho", "s"] + (["Front"] if every_trial else []) + ["Paired"] + [
        PAIRED_OUTCOMES.get(o, o.replace("_", " ")) for o in outcomes]
    rows = [[method_display(str(r["reference"])), str(r["trial"]), _fmt(float(r["_rho"])), str(r["s"])]
            + (["yes" if r["_front"] else ""] if every_trial else []) + [str(r["paired"])]
            + [paired_cell(r, o) for o in outcomes] for _, r in renamed.iterrows()]
    what = "every paired trial, by rho," if every_trial else "the success-spillage front"
    return ReportTable(
        "sweep_reference_all" if every_trial else "sweep_reference", f"Sweep: {what} against the reference, episode by episode",
        "Episodes with each outcome, the reference → the trial, on the validation episodes both ran (same food, level, "
        "trial and seed); (−a +b): episodes that had it only with the reference, only with the trial; p: exact two-sided "
        "sign test (McNemar's exact test) on those, one per trial, not corrected for the trials compared. "
        "An episode with an error is no success and a scoop failure.",
        pd.DataFrame(rows, columns=head), shown.drop(columns=["_front", "_rho"]).reset_index(drop=True),
    )


def _is_true(value: Any) -> bool:
    """A reference.csv flag as pandas, a CSV or a hand edit may hold it: True, "True", " true", 1, 1.0, "yes"."""
    if isinstance(value, str):
        return value.strip().lower() in {"true", "1", "1.0", "yes"}
    return bool(value) and not (isinstance(value, float) and math.isnan(value))
