"""Provenance of a report: what produced the records and what produced the report, and when.

The run's own provenance.json and configs are shown as written; beside them the report adds
the git commit of the code that drew it, package versions (read from installed metadata, so
no heavy package is imported), seeds and episode counts taken from the records themselves.
"""

from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Any

import pandas as pd

from grits_lab.report.run_records import RunData
from grits_lab.versions import PROTOCOL, git_commit, package_versions


def protocol_summary(episodes: pd.DataFrame | None) -> str:
    """The task protocol of the records: `scoop-v4`, or each protocol with its episode count when
    they hold several (every method's rows then carry their protocol in their label)."""
    if episodes is None or episodes.empty or "protocol" not in episodes.columns:
        return "no episode records"
    counts = episodes["protocol"].astype(str).value_counts().sort_index()
    if len(counts) == 1:
        return str(counts.index[0])
    listed = ", ".join(f"{protocol} ({n} episodes)" for protocol, n in counts.items())
    return f"{listed}; every method's rows are labelled with their protocol and never pooled"


def seed_summary(episodes: pd.DataFrame | None) -> dict[str, Any]:
    """Distinct seeds, their range, and whether every method saw the same (food, level, trial) -> seed map."""
    if episodes is None or "seed" not in episodes.columns or episodes.empty:
        return {"seeds": "not recorded"}
    seeds = pd.to_numeric(episodes["seed"], errors="coerce").dropna().astype(int)
    summary: dict[str, Any] = {"distinct seeds": int(seeds.nunique())}
    if len(seeds):
        summary["seed range"] = f"{int(seeds.min())} .. {int(seeds.max())}"
    keys = [c for c in ("food_key", "level", "trial") if c in episodes.columns]
    per_variant = {
        variant: frozenset(map(tuple, rows[[*keys, "seed"]].astype(str).to_numpy()))
        for variant, rows in episodes.groupby("variant")
    }
    if len(per_variant) > 1:
        common = frozenset.intersection(*per_variant.values())
        union = frozenset.union(*per_variant.values())
        summary["same episode seeds for every method"] = (
            "yes" if common == union
            else f"no: {len(common)} of {len(union)} (food, level, trial, seed) episodes are shared by all methods"
        )
    return summary


def episode_counts(episodes: pd.DataFrame | None) -> pd.DataFrame:
    if episodes is None or episodes.empty:
        return pd.DataFrame(columns=["method", "episodes", "errors", "foods", "levels"])
    grouped = episodes.groupby("variant_name", sort=False)
    return pd.DataFrame({
        "method": list(grouped.groups),
        "episodes": grouped.size().to_numpy(),
        "errors": grouped["is_error"].sum().astype(int).to_numpy(),
        "foods": grouped["food_key"].nunique().to_numpy(),
        "levels": grouped["level"].nunique().to_numpy(),
    })


def error_messages(episodes: pd.DataFrame | None, most: int = 10) -> pd.DataFrame:
    """The commonest error messages with their counts, so a reader sees why episodes failed."""
    if episodes is None or not episodes["is_error"].any():
        return pd.DataFrame(columns=["method", "error", "episodes"])
    rows = episodes[episodes["is_error"]]
    counts = rows.groupby(["variant_name", "error"]).size().sort_values(ascending=False).head(most)
    return pd.DataFrame([{"method": m, "error": e[:200], "episodes": int(c)} for (m, e), c in counts.items()])


def report_provenance(run: RunData, out_dir: Path) -> dict[str, Any]:
    episodes = run.episodes
    return {
        "report generated (UTC)": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S"),
        "report code git commit": git_commit(),
        "run directory": str(run.run_dir),
        "task protocol (records)": protocol_summary(episodes),
        "task protocol (report code)": PROTOCOL,
        "output directory": str(out_dir),
        "episode record files": [str(p) for p in run.episode_files],
        "ignored files": run.ignored_files,
        "duplicate rows dropped": run.duplicates_dropped,
        "episodes": 0 if episodes is None else int(len(episodes)),
        "episodes with an error": 0 if episodes is None else int(episodes["is_error"].sum()),
        "run ids": [] if episodes is None or "run_id" not in episodes.columns else sorted(map(str, episodes["run_id"].dropna().unique())),
        "seeds": seed_summary(episodes),
        "sweep trials file": str(run.trials_file) if run.trials_file else None,
        "best parameters file": str(run.best_params_file) if run.best_params_file else None,
        "package versions (report)": package_versions(),
        "run provenance": run.provenance,
    }
