"""An experiment's committed summary: counts with Wilson intervals per method, spills by stage and cause, provenance.

`grits-lab report RUN_DIR --summary-to studies/STUDY/summaries/NAME` writes, into NAME's folder:

    summary.csv       one row per method and outcome: k, n, rate, Wilson 95 % bounds (OUTCOMES)
    stage_cause.csv   one row per method, stage and cause: episodes with such a spill, particles
    claims.csv        the paper's claims beside these records (the report's claims table), when they hold its methods
    paired.csv        every method against Diffusion Policy on the episodes both ran, and a method's settings
                      against its reference setting (run_compare.compare_methods)
    reference.csv     a sweep's trials against its reference methods on the same episodes (the sweep's own file)
    provenance.json   protocol, commits, machine, dates, wall time, checkpoint digests, episodes per method
    config.yaml       the run's config as it ran (RUN_DIR/config.yaml)
    episodes.csv      the episode records themselves, one row per episode (grits_lab/records.py), so that a
                      page is a run the report reads: `grits-lab report NEW_RUN studies/STUDY/summaries/NAME` adds
                      the trials of another sitting or machine (`first_trial`) to the same table

The files count what the records hold and nothing else: a method with fewer episodes than its
config plans has its own n. docs/results.md, the README's table and every experiment page are
rendered from these files (grits_lab/report/results_pages.py).
"""

from __future__ import annotations

import datetime as _dt
import math
import shutil
from pathlib import Path
from typing import Any

import pandas as pd

from grits_lab.intervals import rate
from grits_lab.io import ensure_writable_dir, write_json_atomic, write_text_atomic
from grits_lab.records import CODE_COMMIT, CPU_KERNELS, OUTCOME_COLUMNS
from grits_lab.report.run_compare import PAIRED_METHODS_FILE, compare_methods
from grits_lab.report.run_records import SWEEP_REFERENCE_FILE, RunData
from grits_lab.report.spill_tables import (AFTER_SCOOP, DELIVERED_SHARE, delivered_share, has_attribution,
                                           lifted_episodes, spill_attribution_table, spilled_after_scoop,
                                           spilled_before_pour, spilled_in)
from grits_lab.report.tables import all_variants, claims_table
from grits_lab.report.vocabulary import MAIN_METHODS
from grits_lab.versions import git_commit

SUMMARY_FILE = "summary.csv"
STAGES_FILE = "stage_cause.csv"
CLAIMS_FILE = "claims.csv"
PROVENANCE_FILE = "provenance.json"
CONFIG_FILE = "config.yaml"
EPISODES_FILE = "episodes.csv"
# Columns the report adds when it reads records (run_records.normalize_records); a page keeps the records' own.
DERIVED_COLUMNS = ("is_error", "food_key", "variant", "variant_name")

# outcome -> what k counts, and over which episodes (n).
OUTCOMES: dict[str, str] = {
    "task_success": "task success, of all episodes",
    "spillage": "a spill during the scoop, of all episodes",
    "scoop_failure": "too little lifted, of all episodes",
    "spill_after_scoop": "a particle lost after the scoop (lift, carry, pour or after it), of all episodes",
    **{f"spill_{stage}": f"a particle lost in the {stage.replace('_', ' ')}, of all episodes" for stage in AFTER_SCOOP},
    "spill_before_pour": "a particle lost in the scoop, lift or carry (the spills the scoop and the load it left cause), "
                         "of all episodes",
    "delivered": f"at least {DELIVERED_SHARE:.0%} of the lifted food in the target bowl and nothing lost after the scoop, "
                 "of the episodes that lifted food",
    "reach_check_failed": "no option of the transfer's reach check passed, of the transfers checked",
    "error": "the episode ended with an error (counted as a task failure), of all episodes",
}
SUMMARY_COLUMNS = ("method", "method_name", "outcome", "k", "n", "rate", "ci_low", "ci_high")
STAGE_COLUMNS = ("method", "method_name", "stage", "cause", "episodes_k", "episodes", "particles")


def summary_table(episodes: pd.DataFrame) -> pd.DataFrame:
    """(methods x outcomes) rows of SUMMARY_COLUMNS from normalized records, one method variant at a time.

    Outcomes the records cannot give (records without the stage x cause columns, without
    `scooped` or `transfer_reachable`) are left out, never written as zeros."""
    rows = []
    attributed = has_attribution(episodes)
    for variant, name in all_variants(episodes):
        group = episodes[episodes["variant"] == variant]
        counts: dict[str, tuple[int, int]] = {o: (int(group[o].sum()), len(group)) for o in OUTCOME_COLUMNS}
        if attributed:
            counts["spill_after_scoop"] = (int((spilled_after_scoop(group) > 0).sum()), len(group))
            counts["spill_before_pour"] = (int((spilled_before_pour(group) > 0).sum()), len(group))
            for stage in AFTER_SCOOP:
                counts[f"spill_{stage}"] = (int((spilled_in(group, (stage,)) > 0).sum()), len(group))
            if {"scooped", "transferred"} <= set(group.columns):
                lifted = lifted_episodes(group)
                counts["delivered"] = (int(delivered_share(lifted)[1].sum()), len(lifted))
        if "transfer_reachable" in group.columns:
            checked = group["transfer_reachable"].map(lambda v: None if v is None or (isinstance(v, float) and math.isnan(v)) else bool(v))
            checked = checked[checked.notna()]
            if len(checked):
                counts["reach_check_failed"] = (int((checked == False).sum()), len(checked))  # noqa: E712
        counts["error"] = (int(group["is_error"].sum()), len(group))
        for outcome in OUTCOMES:
            if outcome in counts:
                k, n = counts[outcome]
                r = rate(k, n)
                rows.append({"method": variant, "method_name": name, "outcome": outcome, "k": k, "n": n,
                             "rate": _round(r.rate), "ci_low": _round(r.low), "ci_high": _round(r.high)})
    return pd.DataFrame(rows, columns=list(SUMMARY_COLUMNS))


def stage_cause_table(episodes: pd.DataFrame) -> pd.DataFrame:
    """Per method, stage and cause: episodes with at least one particle lost that way, and the particles
    (the data of the report's `spill_attribution_table`, one row per method variant, stage and cause).

    Empty when the records predate the `spilled_<stage>_<cause>` columns."""
    data = spill_attribution_table(episodes).data
    if data.empty:
        return pd.DataFrame(columns=list(STAGE_COLUMNS))
    return data.assign(method=data["variant"])[list(STAGE_COLUMNS)]


def _weights_digests(runs: dict[str, Any], variant: str) -> dict[str, Any]:
    """{"weights digests (sha256, first 16)": {key: digest}} of a method from the run's provenance.json,
    which records them from scoop-v12's later runs on; {} before that. With the CPU kernels each
    checkpoint was trained on, where the checkpoint recorded them."""
    checkpoints = ((runs.get("methods") or {}).get(variant) or {}).get("checkpoints") or {}
    weights = {key: entry["weights_sha256_16"] for key, entry in sorted(checkpoints.items())
               if isinstance(entry, dict) and entry.get("weights_sha256_16")}
    trained = {key: entry["trained on cpu kernels"] for key, entry in sorted(checkpoints.items())
               if isinstance(entry, dict) and entry.get("trained on cpu kernels")}
    return ({"weights digests (sha256, first 16)": weights} if weights else {}) | (
        {"trained on cpu kernels": trained} if trained else {})


def _code_commits(group: pd.DataFrame) -> dict[str, Any]:
    """{"code commits": [commit, ...]}: the commits the records of one method name (`code_commit`,
    grits_lab/records.py), sorted; {} where none does (records from before the column)."""
    if CODE_COMMIT not in group or not group[CODE_COMMIT].notna().any():
        return {}
    return {"code commits": sorted(map(str, group[CODE_COMMIT].dropna().unique()))}


def _machine(runs: dict[str, Any], episodes: pd.DataFrame) -> dict[str, Any]:
    """Host, CPU and packages from provenance.json, and episodes per CPU-kernel label from the records
    (`cpu_kernels`, grits_lab/versions.py); the CPU entries only where the run recorded them."""
    machine: dict[str, Any] = {"host": runs.get("host")}
    if runs.get("cpu"):
        machine["cpu"] = runs["cpu"]
    if CPU_KERNELS in episodes and episodes[CPU_KERNELS].notna().any():
        counts = episodes[CPU_KERNELS].dropna().astype(str).value_counts()
        machine["cpu kernels (episodes)"] = {str(k): int(v) for k, v in sorted(counts.items())}
    machine["packages"] = runs.get("packages", {})
    return machine


def _sweep_started(trials: pd.DataFrame | None) -> str | None:
    """A sweep's start: its earliest trial's `datetime_start` in UTC (trials.csv writes UTC-aware times,
    grits_lab/tune/outputs.py; a time without an offset is read as UTC), None without one. A sweep keeps
    no provenance.json: its trials may run on several machines."""
    if trials is None or "datetime_start" not in trials:
        return None
    started = pd.to_datetime(trials["datetime_start"].astype(str), utc=True, format="ISO8601", errors="coerce").dropna()
    return started.min().strftime("%Y-%m-%d %H:%M:%S") if len(started) else None


def summary_provenance(run: RunData, command: str) -> dict[str, Any]:
    """What produced the records (from the run's provenance.json and the records) and the summary."""
    episodes = run.episodes
    runs = run.provenance.get("provenance.json", {}) if isinstance(run.provenance.get("provenance.json"), dict) else {}
    per_method = {}
    for variant, name in all_variants(episodes):
        group = episodes[episodes["variant"] == variant]
        digests = {column.removeprefix("checkpoint_"): sorted(map(str, group[column].dropna().unique()))
                   for column in sorted(c for c in group.columns if c.startswith("checkpoint_")) if group[column].notna().any()}
        trials = sorted(int(t) for t in pd.to_numeric(group["trial"], errors="coerce").dropna().unique()) if "trial" in group else []
        per_method[variant] = {
            "name": name,
            "episodes": len(group),
            "trials": trials,
            "foods": int(group["food_key"].nunique()),
            "levels": sorted(map(str, group["level"].unique())),
            "checkpoint digests (sha256, first 16)": digests,
            **_weights_digests(runs, variant),
            **_code_commits(group),
            "episode wall time (s, summed)": round(float(pd.to_numeric(group.get("wall_time_s"), errors="coerce").sum()), 1)
            if "wall_time_s" in group else None,
        }
    return {
        "command": command,
        "run directories": [str(run.run_dir), *map(str, run.also_runs)],
        "protocol": sorted(map(str, episodes["protocol"].unique())) if "protocol" in episodes else [],
        "records' code commit": runs.get("code git commit"),
        "run started (UTC)": runs.get("started (UTC)") or _sweep_started(run.trials),
        "machine": _machine(runs, episodes),
        "episodes": int(len(episodes)),
        "episode wall time (s, summed)": round(float(pd.to_numeric(episodes["wall_time_s"], errors="coerce").sum()), 1)
        if "wall_time_s" in episodes else None,
        "methods": per_method,
        "summary code commit": git_commit(),
        "summary written (UTC)": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S"),
    }


def write_summary(run: RunData, out_dir: str | Path, command: str) -> list[Path]:
    """Write summary.csv, stage_cause.csv, claims.csv, paired.csv, reference.csv, provenance.json and
    config.yaml into `out_dir` (a claims.csv, paired.csv or reference.csv left by an earlier summary of
    other records is removed when these hold none of the paper's methods, no method to pair with
    Diffusion Policy, or no sweep reference)."""
    from grits_lab.errors import InputError

    if run.episodes is None or run.episodes.empty:
        raise InputError(f"--summary-to needs episode records; {run.run_dir} has none")
    out = Path(out_dir)
    ensure_writable_dir(out)
    provenance = summary_provenance(run, command)  # before any write: a page in the checkout would mark it changed
    files = []
    tables = [(SUMMARY_FILE, summary_table(run.episodes)), (STAGES_FILE, stage_cause_table(run.episodes))]
    if run.episodes["method"].isin(MAIN_METHODS).any():  # the paper's claims concern its methods, not the oracle
        tables.append((CLAIMS_FILE, claims_table(run.episodes).display))
    if not (paired := compare_methods(run.episodes)).empty:
        tables.append((PAIRED_METHODS_FILE, paired))
    if run.sweep_reference is not None and not run.sweep_reference.empty:
        tables.append((SWEEP_REFERENCE_FILE, run.sweep_reference))
    for name, frame in tables:
        write_text_atomic(out / name, frame.to_csv(index=False, lineterminator="\n"))
        files.append(out / name)
    for name in (CLAIMS_FILE, PAIRED_METHODS_FILE, SWEEP_REFERENCE_FILE):
        if name not in dict(tables):
            (out / name).unlink(missing_ok=True)
    write_text_atomic(out / EPISODES_FILE, episodes_csv(run.episodes))
    files.append(out / EPISODES_FILE)
    write_json_atomic(out / PROVENANCE_FILE, provenance)
    files.append(out / PROVENANCE_FILE)
    config = (run.run_dir if run.run_dir.is_dir() else run.run_dir.parent) / CONFIG_FILE
    if config.is_file():
        shutil.copyfile(config, out / CONFIG_FILE)
        files.append(out / CONFIG_FILE)
    return files


def episodes_csv(episodes: pd.DataFrame) -> str:
    """The records as a page keeps them: every record column, rows in (method, food, level, trial) order,
    floats at full precision, so that reading the file back reproduces every table of the page."""
    frame = episodes.drop(columns=[c for c in DERIVED_COLUMNS if c in episodes.columns])
    order = [c for c in ("method", "food", "level", "trial", "rho", "s") if c in frame.columns]
    frame = frame.sort_values(order, kind="stable") if order else frame
    return frame.to_csv(index=False, lineterminator="\n")


def _round(value: float) -> float:
    return value if math.isnan(value) else round(value, 6)
