"""The report's tables: each builder turns normalized episode records into one ReportTable.

A ReportTable holds two frames: `display` (strings, what Markdown, LaTeX and HTML show, with
missing cells as "—") and `data` (numbers, what the CSV holds, with missing cells empty).
A method or food without records gets a row marked missing, never a rate of zero, and is
named in the table's notes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pandas as pd

from grits_lab.records import OUTCOME_COLUMNS
from grits_lab.sim.spill_metrics import SPILL_STAGES, attribution_columns
from grits_lab.intervals import Rate, format_percent, format_rate, rate
from grits_lab.report.vocabulary import (
    ABLATION_METHODS,
    FOOD_ABBREVIATIONS,
    LEVEL_ORDER,
    MAIN_METHODS,
    MISSING,
    OUTCOME_NAMES,
    PAPER_LABEL,
    PAPER_RESULTS,
    PAPER_SPILLAGE_REDUCTION_VS_DP,
    PAPER_TRIALS_PER_METHOD,
    PER_FOOD_METHODS,
    SIM_LABEL,
    UNSEEN_FOODS,
    food_display,
    method_display,
    ordered,
)

# Paper Fig. 6 classifies each trial once, in this order of precedence.
PER_FOOD_CATEGORIES = ("success", "spillage", "scoop_failure", "other_failure", "error")
PER_FOOD_CATEGORY_NAMES = {
    "success": "Success",
    "spillage": "Spillage (before scoop)",
    "scoop_failure": "Scoop failure",
    "other_failure": "Other failure",
    "error": "Error",
}


@dataclass
class ReportTable:
    key: str
    title: str
    caption: str
    display: pd.DataFrame
    data: pd.DataFrame
    notes: list[str] = field(default_factory=list)
    # A table too wide for a laptop's window is shown as these narrower ones, each under its
    # subtitle (one per method); `display` and the CSV keep the whole table.
    parts: list[tuple[str, pd.DataFrame]] = field(default_factory=list)


def outcome_rates(rows: pd.DataFrame) -> dict[str, Rate]:
    n = len(rows)
    return {o: rate(int(rows[o].sum()) if n else 0, n) for o in OUTCOME_COLUMNS}


def variants_of(episodes: pd.DataFrame | None, method: str) -> list[tuple[str, str]]:
    """(variant, display name) pairs recorded for `method`, in a stable order."""
    if episodes is None or episodes.empty:
        return []
    rows = episodes.loc[episodes["method"] == method, ["variant", "variant_name"]].drop_duplicates()
    return sorted(rows.itertuples(index=False, name=None))


def method_table(
    episodes: pd.DataFrame | None, methods: tuple[str, ...], key: str, title: str, caption: str, extra: bool = False
) -> ReportTable:
    """Method x {task success, spillage, scoop failure}: rates, Wilson 95% intervals, counts, paper numbers.

    With `extra`, methods found in the records but absent from `methods` and from the ablation
    are appended, so that no evaluated method is silently left out of the report.
    """
    method_list = list(methods)
    if extra and episodes is not None:
        known = set(MAIN_METHODS) | set(ABLATION_METHODS)
        method_list += [m for m in ordered(episodes["method"].unique(), ()) if m not in known]
    display_rows, data_rows, missing = [], [], []
    for method in method_list:
        variants = variants_of(episodes, method)
        if not variants:
            missing.append(method_display(method))
            variants = [(method, method_display(method))]
        paper = PAPER_RESULTS.get(method, {})
        for variant, name in variants:
            rows = episodes[episodes["variant"] == variant] if episodes is not None else pd.DataFrame()
            rates = outcome_rates(rows) if len(rows) else {o: rate(0, 0) for o in OUTCOME_COLUMNS}
            errors = int(rows["is_error"].sum()) if len(rows) else 0
            shown = {"Method": name, "Episodes": str(len(rows)) if len(rows) else MISSING,
                     "Errors": str(errors) if len(rows) else MISSING}
            data = {"method": method, "variant": variant, "method_name": name, "episodes": len(rows),
                    "errors": errors if len(rows) else math.nan, "missing": not len(rows)}
            for outcome in OUTCOME_COLUMNS:
                r = rates[outcome]
                label = OUTCOME_NAMES[outcome]
                shown[f"{label} ({SIM_LABEL})"] = format_rate(r)
                shown[f"{label} ({PAPER_LABEL})"] = format_percent(paper.get(outcome))
                data.update({
                    f"{outcome}_k": r.k if not r.missing else math.nan, f"{outcome}_rate": r.rate,
                    f"{outcome}_ci_low": r.low, f"{outcome}_ci_high": r.high,
                    f"{outcome}_paper": paper.get(outcome, math.nan),
                })
            display_rows.append(shown)
            data_rows.append(data)
    notes = [
        "Simulated cells: rate [Wilson 95% interval] (episodes with the outcome / episodes). "
        f"Paper cells: real robot, {PAPER_TRIALS_PER_METHOD} trials per method; blank where the paper gives no number.",
        "Outcomes may overlap (a trial can spill and still fail to scoop). Episodes that ended with an error count as task failures.",
    ]
    if missing:
        notes.insert(0, f"Missing (no episode records): {', '.join(missing)}.")
    return ReportTable(key, title, caption, pd.DataFrame(display_rows), pd.DataFrame(data_rows), notes)


def per_food_category(rows: pd.DataFrame) -> pd.Series:
    """Each trial's single Fig. 6 category: error, else spillage before the scoop, else scoop failure, else success."""
    category = pd.Series("other_failure", index=rows.index)
    category[rows["task_success"]] = "success"
    category[rows["scoop_failure"]] = "scoop_failure"
    category[rows["spilled_before_scoop"]] = "spillage"
    category[rows["is_error"]] = "error"
    return category


def per_food_table(episodes: pd.DataFrame | None) -> ReportTable:
    """Paper Fig. 6: per food, Diffusion Policy vs GRITS, counting spillage before the scoop completes."""
    key, title = "fig6_per_food", "Fig. 6: per food, Diffusion Policy vs GRITS"
    caption = (
        "A trial is a spillage failure if food spilled at any point before the scoop completed, whether "
        "or not food was lifted afterwards; otherwise a scoop failure if too little was lifted; otherwise "
        "a success if the task succeeded; remaining trials (e.g. spillage during transfer) are other failures."
    )
    variants = [v for m in PER_FOOD_METHODS for v in (variants_of(episodes, m) or [(m, method_display(m))])]
    notes = []
    if episodes is not None and "spilled_before_scoop" not in episodes.columns:
        notes.append("Missing: the records have no `spilled_before_scoop` column, so Fig. 6 cannot be computed.")
        return ReportTable(key, title, caption, pd.DataFrame(), pd.DataFrame(), notes)
    foods = list(UNSEEN_FOODS)
    if episodes is not None:
        sub = episodes[episodes["method"].isin(PER_FOOD_METHODS)]
        foods += [f for f in ordered(sub["food_key"].unique(), ()) if f not in FOOD_ABBREVIATIONS]
    display_rows, data_rows = [], []
    parts: dict[str, list[dict[str, str]]] = {name: [] for _, name in variants}
    for food in [*foods, None]:
        shown = {"Food": "All foods" if food is None else food_display(food, long=True)}
        for variant, name in variants:
            # The last row pools every food of the method (no food filter).
            rows = _select(episodes, variant=variant, **({} if food is None else {"food_key": food}))
            counts = per_food_category(rows).value_counts() if len(rows) else pd.Series(dtype=int)
            part = {"Food": shown["Food"], "Episodes": str(len(rows)) if len(rows) else MISSING}
            for category in PER_FOOD_CATEGORIES:
                k = int(counts.get(category, 0))
                r = rate(k, len(rows))
                part[PER_FOOD_CATEGORY_NAMES[category]] = (
                    format_rate(r) if food is None else f"{k}" if len(rows) else MISSING)
                data_rows.append({
                    "food": "all" if food is None else food, "abbreviation": FOOD_ABBREVIATIONS.get(food, ""),
                    "method": variant.split("[")[0], "variant": variant, "method_name": name, "category": category,
                    "k": k if len(rows) else math.nan, "episodes": len(rows),
                    "rate": r.rate, "ci_low": r.low, "ci_high": r.high,
                })
            parts[name].append(part)
            shown.update({f"{name}: {column.lower() if column == 'Episodes' else column}": value
                          for column, value in part.items() if column != "Food"})
        display_rows.append(shown)
    missing = [
        f"{name}: {', '.join(food_display(f, long=True) for f in foods if not len(_select(episodes, variant=v, food_key=f)))}"
        for v, name in variants
        if any(not len(_select(episodes, variant=v, food_key=f)) for f in foods)
    ]
    if missing:
        notes.append("Missing (no episode records): " + "; ".join(missing) + ".")
    notes.append("Cells are episode counts per food; the last row gives rates with Wilson 95% intervals over all foods.")
    return ReportTable(key, title, caption, pd.DataFrame(display_rows), pd.DataFrame(data_rows), notes,
                       parts=[(name, pd.DataFrame(rows)) for name, rows in parts.items()])


def breakdown_long(episodes: pd.DataFrame) -> pd.DataFrame:
    """Every method variant x food x level with counts, rates and Wilson intervals (CSV only)."""
    rows = []
    for (variant, food, level), group in episodes.groupby(["variant", "food_key", "level"], sort=True):
        data = {"method": group["method"].iloc[0], "variant": variant, "method_name": group["variant_name"].iloc[0],
                "food": food, "abbreviation": FOOD_ABBREVIATIONS.get(food, ""), "level": level,
                "episodes": len(group), "errors": int(group["is_error"].sum())}
        for outcome, r in outcome_rates(group).items():
            data.update({f"{outcome}_k": r.k, f"{outcome}_rate": r.rate,
                         f"{outcome}_ci_low": r.low, f"{outcome}_ci_high": r.high})
        rows.append(data)
    return pd.DataFrame(rows)


def breakdown_tables(episodes: pd.DataFrame | None) -> list[ReportTable]:
    """Per food x quantity level, one table per outcome, one column per method: `k/n` cells."""
    if episodes is None or episodes.empty:
        return []
    long = breakdown_long(episodes)
    variants = all_variants(episodes)
    foods = list(UNSEEN_FOODS) + [f for f in ordered(episodes["food_key"].unique(), ()) if f not in FOOD_ABBREVIATIONS]
    levels = ordered(episodes["level"].unique(), LEVEL_ORDER)
    tables = []
    for outcome in OUTCOME_COLUMNS:
        display_rows, data_rows, missing_cells = [], [], {}
        for food in foods:
            for level in levels:
                shown = {"Food": food_display(food, long=True), "Level": level}
                data = {"food": food, "level": level}
                for variant, name in variants:
                    cell = long[(long["variant"] == variant) & (long["food"] == food) & (long["level"] == level)]
                    if cell.empty:
                        shown[name] = MISSING
                        missing_cells.setdefault(name, {}).setdefault(food_display(food, long=True), []).append(level)
                        data.update({f"{variant}_k": math.nan, f"{variant}_n": 0, f"{variant}_rate": math.nan})
                    else:
                        k, n = int(cell[f"{outcome}_k"].iloc[0]), int(cell["episodes"].iloc[0])
                        shown[name] = f"{k}/{n}"
                        data.update({f"{variant}_k": k, f"{variant}_n": n, f"{variant}_rate": k / n})
                display_rows.append(shown)
                data_rows.append(data)
        notes = ["Cells: episodes with the outcome / episodes; — marks a (food, level) with no records for that method."]
        if missing_cells:
            listed = "; ".join(
                f"{name}: " + ", ".join(f"{food} ({', '.join(levels)})" for food, levels in foods_missing.items())
                for name, foods_missing in missing_cells.items()
            )
            notes.insert(0, f"Missing (no episode records) per food and level: {listed}.")
        tables.append(ReportTable(
            f"breakdown_{outcome}", f"Per food x quantity level: {OUTCOME_NAMES[outcome].lower()}",
            f"{OUTCOME_NAMES[outcome]} per food and quantity level for every evaluated method.",
            pd.DataFrame(display_rows), pd.DataFrame(data_rows), notes,
        ))
    return tables


def claims_table(episodes: pd.DataFrame | None) -> ReportTable:
    """The paper's headline numbers and claims beside their simulated counterparts."""
    display_rows, data_rows = [], []

    def add(quantity: str, paper: str, simulated: str, paper_value: float, sim_value: float, note: str = "") -> None:
        display_rows.append({"Quantity": quantity, PAPER_LABEL: paper, SIM_LABEL: simulated, "Note": note})
        data_rows.append({"quantity": quantity, "paper": paper_value, "simulation": sim_value, "note": note})

    for method, numbers in PAPER_RESULTS.items():
        for variant, name in variants_of(episodes, method) or [(method, method_display(method))]:
            rows = _select(episodes, variant=variant)
            rates = outcome_rates(rows)
            for outcome, value in numbers.items():
                r = rates[outcome]
                add(f"{name}: {OUTCOME_NAMES[outcome].lower()}", format_percent(value), format_rate(r), value, r.rate,
                    "" if len(rows) else "no simulated episodes")
    dp_variants = variants_of(episodes, "dp")
    for variant, name in variants_of(episodes, "grits") or [("grits", "GRITS")]:
        g = outcome_rates(_select(episodes, variant=variant))
        for dp_variant, dp_name in dp_variants or [("dp", "Diffusion Policy")]:
            d = outcome_rates(_select(episodes, variant=dp_variant))
            reduction = _relative_reduction(g["spillage"], d["spillage"])
            # A verdict only where the Wilson intervals are apart; overlapping ones decide nothing either way.
            n = g["spillage"].n if g["spillage"].n == d["spillage"].n else f"{d['spillage'].n} and {g['spillage'].n}"
            note = ("needs both methods' records" if g["spillage"].missing or d["spillage"].missing
                    else "undefined: no spillage without guidance" if math.isnan(reduction)
                    else "does not hold: GRITS spilled more, Wilson intervals apart" if d["spillage"].high < g["spillage"].low
                    else f"undecided at n = {n}: Wilson intervals overlap" if g["spillage"].high >= d["spillage"].low
                    else "holds, Wilson intervals apart" if reduction > PAPER_SPILLAGE_REDUCTION_VS_DP
                    else "GRITS spilled less, Wilson intervals apart, by less than the paper's reduction")
            add(f"Spillage reduction, {name} relative to {dp_name}",
                f"> {100 * PAPER_SPILLAGE_REDUCTION_VS_DP:.0f}%", format_percent(reduction),
                PAPER_SPILLAGE_REDUCTION_VS_DP, reduction, note)
            higher = g["scoop_failure"].rate > d["scoop_failure"].rate
            pair_missing = g["scoop_failure"].missing or d["scoop_failure"].missing
            add(f"Scoop failure, {name} vs {dp_name}", "slightly higher for GRITS",
                MISSING if pair_missing else f"{format_percent(g['scoop_failure'].rate)} vs {format_percent(d['scoop_failure'].rate)}",
                math.nan, (g["scoop_failure"].rate - d["scoop_failure"].rate) if not pair_missing else math.nan,
                "needs both methods' records" if pair_missing else ("higher" if higher else "not higher"))
    ablation = {m: outcome_rates(_select(episodes, method=m)) for m in ABLATION_METHODS}
    several = [method_display(m) for m in ABLATION_METHODS if len(variants_of(episodes, m)) > 1]
    if several:  # variants (settings, predictors, protocols) are compared in Fig. 8, never pooled here
        add("Ablation: composite cloud + DP3 beats raw cloud and PointNet++ on success and spillage", "yes",
            MISSING, 1.0, math.nan, f"several variants of {', '.join(several)}: see Fig. 8")
    elif all(not r["task_success"].missing for r in ablation.values()):
        g = ablation["grits"]
        others = [ablation[m] for m in ABLATION_METHODS if m != "grits"]
        best = all(g["task_success"].rate > o["task_success"].rate and g["spillage"].rate < o["spillage"].rate for o in others)
        add("Ablation: composite cloud + DP3 beats raw cloud and PointNet++ on success and spillage", "yes",
            "yes" if best else "no", 1.0, float(best), "point estimates; see Fig. 8 for intervals")
    else:
        absent = [method_display(m) for m, r in ablation.items() if r["task_success"].missing]
        add("Ablation: composite cloud + DP3 beats raw cloud and PointNet++ on success and spillage", "yes",
            MISSING, 1.0, math.nan, f"missing: {', '.join(absent)}")
    return ReportTable(
        "paper_vs_simulation", "The paper's numbers beside the simulation",
        f"'{PAPER_LABEL}': the paper's real-robot results (SPEC, Headline results); '{SIM_LABEL}': this run. "
        "Relative spillage reduction = 1 - spillage(GRITS) / spillage(Diffusion Policy).",
        pd.DataFrame(display_rows), pd.DataFrame(data_rows),
        ["Simulated rates carry Wilson 95% intervals and counts; with ~100 episodes per method an interval is about +-8 points."],
    )


def _relative_reduction(guided: Rate, unguided: Rate) -> float:
    if guided.missing or unguided.missing or unguided.rate == 0:
        return math.nan
    return 1.0 - guided.rate / unguided.rate


def all_variants(episodes: pd.DataFrame) -> list[tuple[str, str]]:
    methods = ordered(episodes["method"].unique(), (*MAIN_METHODS, *ABLATION_METHODS))
    return [v for m in methods for v in variants_of(episodes, m)]


def _select(episodes: pd.DataFrame | None, **equal: object) -> pd.DataFrame:
    if episodes is None:
        return pd.DataFrame(columns=["is_error", *OUTCOME_COLUMNS])
    mask = pd.Series(True, index=episodes.index)
    for column, value in equal.items():
        mask &= episodes[column] == value
    return episodes[mask]


def setting_table(episodes: pd.DataFrame) -> ReportTable:
    """Per method and guidance setting (rho, s): rates with Wilson 95% intervals, from sweep trial records.

    Records of more than one task protocol get a row per protocol (a Protocol column), never pooled."""
    display_rows, data_rows = [], []
    by_protocol = "protocol" in episodes.columns and episodes["protocol"].nunique() > 1
    keys = ["method", "rho", "s", *(["protocol"] if by_protocol else [])]
    for key, rows in episodes.groupby(keys, dropna=False, sort=True):
        method, rho, s = key[:3]
        rates = outcome_rates(rows)
        shown = {"Method": method_display(method), "rho": MISSING if pd.isna(rho) else f"{rho:.4g}", "s": str(s),
                 **({"Protocol": str(key[3])} if by_protocol else {}),
                 "Episodes": str(len(rows)), "Errors": str(int(rows["is_error"].sum()))}
        data = {"method": method, "rho": rho, "s": s, **({"protocol": key[3]} if by_protocol else {}),
                "episodes": len(rows), "errors": int(rows["is_error"].sum())}
        for outcome, r in rates.items():
            shown[OUTCOME_NAMES[outcome]] = format_rate(r)
            data.update({f"{outcome}_k": r.k, f"{outcome}_rate": r.rate, f"{outcome}_ci_low": r.low, f"{outcome}_ci_high": r.high})
        display_rows.append(shown)
        data_rows.append(data)
    return ReportTable(
        "sweep_settings", "Sweep: outcomes per guidance setting",
        "Every (rho, s) the sweep evaluated, from its per-episode records: rate [Wilson 95%] (k/n).",
        pd.DataFrame(display_rows), pd.DataFrame(data_rows),
        ["Neighbouring settings whose intervals overlap are not distinguishable with these episode counts."],
    )


# Why a task failed, by the stage that ended it (grits_lab/evaluation/task_episode.py): each
# episode falls in exactly one of these, in this order.
# A joint moving more than this in one 0.1 s action is the IK leaving for another arm posture:
# reachable transfers measured at most 0.40 rad, the flips 0.5-1.8 rad (docs/archive/notes/history.md).
POSTURE_FLIP_RAD = 0.5

FAILURE_STAGES = (
    ("task_success", "Task success"),
    ("error", "Error"),
    ("scoop_spill", "Spill during the scoop"),
    ("scoop_failure", "Scoop failure (no spill)"),
    ("transfer_spill", "Spill in the transfer or pour"),
    ("not_delivered", "Too little delivered (no spill)"),
)


def failure_stages(rows: pd.DataFrame) -> dict[str, pd.Series]:
    """Boolean masks over `rows` (normalized records), one per FAILURE_STAGES key, and "after_scoop".

    Built in the task's order, each from what the earlier ones left, so they partition the rows
    whatever the record source: an error, then a spill during the scoop, then a scoop failure,
    then success, and what is left ("after_scoop") failed after a clean scoop. That is split by
    `spilled_transfer` (particles spilled in the transfer and pour, recorded by `grits-lab
    evaluate`) into "transfer_spill" and "not_delivered"; without that column both are all-NaN
    masks and only their union, "after_scoop", is known.
    """
    ok = ~rows["is_error"]
    scoop_spill = ok & rows["spillage"]
    scoop_failure = ok & ~scoop_spill & rows["scoop_failure"]
    clean_scoop = ok & ~scoop_spill & ~scoop_failure
    after_scoop = clean_scoop & ~rows["task_success"]
    masks = {"task_success": clean_scoop & rows["task_success"], "error": rows["is_error"], "scoop_spill": scoop_spill,
             "scoop_failure": scoop_failure, "after_scoop": after_scoop}
    transfer_spilled = pd.to_numeric(rows["spilled_transfer"], errors="coerce") if "spilled_transfer" in rows.columns else None
    if transfer_spilled is not None and transfer_spilled[after_scoop].notna().all():
        masks["transfer_spill"] = after_scoop & (transfer_spilled > 0)
        masks["not_delivered"] = after_scoop & ~(transfer_spilled > 0)
    else:
        masks["transfer_spill"] = masks["not_delivered"] = pd.Series(math.nan, index=rows.index)
    return masks


def attribution_counts(rows: pd.DataFrame) -> pd.DataFrame:
    """(episodes x 25) integer particle counts, columns `spilled_<stage>_<cause>`; errors count zero."""
    counts = rows[list(attribution_columns())].apply(pd.to_numeric, errors="coerce").fillna(0).astype(int)
    if "is_error" in rows.columns:
        counts[rows["is_error"].to_numpy()] = 0
    return counts


def spilled_in(rows: pd.DataFrame, stages: tuple[str, ...]) -> pd.Series:
    """(episodes,) particles spilled in any of `stages` (names of SPILL_STAGES), from the attribution columns."""
    counts = attribution_counts(rows)
    return counts[[c for c, (stage, _) in attribution_columns().items() if stage in stages]].sum(axis=1)


def failure_table(episodes: pd.DataFrame | None) -> ReportTable:
    """Method x the stage that ended each episode (FAILURE_STAGES): counts of k / episodes.

    Also counts the transfers in which the arm met a pose it could not reach
    (`transfer_ik_failures` > 0), where the records hold that column.
    """
    display_rows, data_rows = [], []
    merged = False
    for variant, name in all_variants(episodes) if episodes is not None and not episodes.empty else []:
        rows = episodes[episodes["variant"] == variant]
        n = len(rows)
        masks = failure_stages(rows)
        shown: dict[str, str] = {"Method": name, "Episodes": str(n)}
        data: dict[str, object] = {"method": rows["method"].iloc[0], "variant": variant, "method_name": name, "episodes": n}
        for key, label in FAILURE_STAGES:
            mask = masks[key]
            if mask.isna().all():
                merged = True
                shown[label] = MISSING
                data[f"{key}_k"] = math.nan
                if key == "not_delivered":
                    k = int(masks["after_scoop"].sum())
                    shown[label] = f"{k}/{n} (with the spills)"
                    data["after_scoop_k"] = k
            else:
                k = int(mask.astype(bool).sum())
                shown[label] = f"{k}/{n}"
                data[f"{key}_k"] = k
        attributed = all(c in rows.columns for c in attribution_columns())
        if attributed:  # the transfer's spills split by the stage that lost them (episodes with a spill there)
            parts = []
            for stage in SPILL_STAGES[1:]:
                k = int((spilled_in(rows, (stage,)) > 0).sum())
                data[f"spill_{stage}_k"] = k
                parts.append(f"{stage.replace('_', ' ')} {k}")
            shown["Spills after the scoop, by stage"] = " · ".join(parts)
        else:
            shown["Spills after the scoop, by stage"] = MISSING
        recorded = {"transfer_ik_failures", "transfer_max_joint_step_rad"} <= set(rows.columns)
        if recorded:
            ik = pd.to_numeric(rows["transfer_ik_failures"], errors="coerce")
            transfers = pd.to_numeric(rows["transfer_max_joint_step_rad"], errors="coerce").notna() & ~rows["is_error"]
        if recorded and transfers.any():
            k = int(((ik > 0) & transfers).sum())
            n_transfers = int(transfers.sum())
            if "transfer_max_joint_speed_ratio" in rows.columns and pd.to_numeric(rows["transfer_max_joint_speed_ratio"], errors="coerce")[transfers].notna().all():
                flips = int(((pd.to_numeric(rows["transfer_max_joint_speed_ratio"], errors="coerce") > 1.0) & transfers).sum())
            else:  # records made before the Panda's limits were recorded
                step = pd.to_numeric(rows["transfer_max_joint_step_rad"], errors="coerce")
                flips = int(((step > POSTURE_FLIP_RAD) & transfers).sum())
            shown["Transfers with an unreachable pose"] = f"{k}/{n_transfers}"
            shown["Posture flips"] = f"{flips}/{n_transfers}"
            data.update({"transfer_unreachable_k": k, "posture_flip_k": flips, "transfers": n_transfers})
        else:
            shown["Transfers with an unreachable pose"] = shown["Posture flips"] = MISSING
            data.update({"transfer_unreachable_k": math.nan, "posture_flip_k": math.nan, "transfers": math.nan})
        checked = (pd.Series(rows["transfer_reachable"].tolist(), index=rows.index, dtype=object)
                   if "transfer_reachable" in rows.columns else pd.Series(None, index=rows.index, dtype=object))
        checked = checked.map(lambda v: None if v is None or (isinstance(v, float) and math.isnan(v)) else bool(v))
        if checked.notna().any():
            failed = int((checked == False).sum())  # noqa: E712 (None is neither)
            shown["Reach check failed"] = f"{failed}/{int(checked.notna().sum())}"
            data.update({"reach_check_failed_k": failed, "reach_checked": int(checked.notna().sum())})
        else:
            shown["Reach check failed"] = MISSING
            data.update({"reach_check_failed_k": math.nan, "reach_checked": math.nan})
        display_rows.append(shown)
        data_rows.append(data)
    notes = [
        "Each episode is counted once, at the first stage that ended it: an error, a spill during the scoop, a scoop "
        "that carried too little, a spill in the transfer or pour, or, without any spill, less food in the target "
        "bowl than the task asks (one item, or half the scooped particles): the rest stayed on the spoon or fell "
        "back into the source bowl.",
        "Transfers with an unreachable pose: transfers (and pours) of episodes without an error with at least one "
        "action whose pose the arm could not reach (`transfer_ik_failures`); the IK may then find the pose in "
        "another arm posture, and the flip throws the load. The first action of a checked transfer may be one: it "
        "starts from the scoop's last command, which the arm may have stopped short of.",
        "Posture flips: transfers with an action that asked a joint to move faster than the Panda's velocity limit "
        "(`transfer_max_joint_speed_ratio` > 1: 0.22-0.26 rad in one 0.1 s action; from scoop-v8 on such an action is "
        "slowed to the limit, `sim.joint_speed_cap`); for records that predate it, "
        f"more than {POSTURE_FLIP_RAD} rad in one action (`transfer_max_joint_step_rad`; the flips measured 0.5-1.8 rad).",
        "Spills after the scoop, by stage: episodes with a particle lost in the lift, the carry, the pour and after the "
        "pour (an episode may lose food in more than one); the next table gives the causes.",
        "Reach check failed: transfers for which no option of the reach check (docs/evaluation.md) passed "
        "(`transfer_reachable`); the one that went farthest was executed. '-' where the records predate the check.",
    ]
    if merged:
        notes.insert(0, "(with the spills): these records lack `spilled_transfer`, so the failures after a clean "
                        "scoop are counted together, under 'Too little delivered'.")
    return ReportTable("failure_stages", "Why tasks failed: the stage that ended each episode",
                       "Per method, episodes by the first stage that ended them.",
                       pd.DataFrame(display_rows), pd.DataFrame(data_rows), notes)
