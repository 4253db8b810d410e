"""Dataset summary for `grits-lab dataset info`: counts by food, shape and label, failures and size on disk."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from grits_lab.config import parse_yaml
from grits_lab.data.chunk_labels import TRIAL_LABELS
from grits_lab.data.format import EPISODE_DIR, MANIFEST_FILE, load_index, rebuild_index
from grits_lab.errors import StorageError
from grits_lab.sim.spill_metrics import attribution_columns
from grits_lab.records import UNVERSIONED


def dataset_summary(path: str | Path) -> dict[str, Any]:
    """A plain-dict summary of the dataset at `path` (rebuilding a missing or stale index)."""
    path = Path(path)
    if not (path / MANIFEST_FILE).is_file():
        raise StorageError(f"not a grits-lab dataset (no {MANIFEST_FILE}): {path}")
    manifest = parse_yaml((path / MANIFEST_FILE).read_text(), path / MANIFEST_FILE) or {}
    n_files = len(list((path / EPISODE_DIR).glob("*.npz")))
    index = load_index(path)
    if len(index) != n_files:
        index = rebuild_index(path, on_corrupt="skip")
    size = sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    out: dict[str, Any] = {
        "path": str(path),
        "kind": manifest.get("kind"),
        "format_version": manifest.get("format_version"),
        "protocol": manifest.get("protocol", UNVERSIONED),
        "status": manifest.get("status"),
        "episodes": int(len(index)),
        "failed": len(list((path / "failures").glob("*.json"))),
        "size_mb": round(size / 2**20, 2),
    }
    config = manifest.get("config") if isinstance(manifest.get("config"), dict) else {}
    balanced = TRIAL_LABELS[config.get("balance_on", "chunk")]  # the label a spillage dataset's buckets hold
    for column in ("food", "level", "shape", "label", "label_horizon"):
        if column in index.columns:
            out[f"by_{column}"] = {str(k): int(v) for k, v in index[column].dropna().value_counts().sort_index().items()}
    if {"shape", balanced} <= set(index.columns):
        out["by_shape_label"] = {
            f"{s}/{int(l)}": int(n) for (s, l), n in index.dropna(subset=[balanced]).groupby(["shape", balanced]).size().items()
        }
    for column in ("scoop_success", "spilled_any", "label", "label_horizon"):
        if column in index.columns and len(index):
            out[f"mean_{column}"] = round(float(index[column].astype(float).mean()), 3)
    out.update(chunk_label_rates(index))
    if {"food", "level", "scoop_success", "spilled_any"} <= set(index.columns) and len(index):
        out["by_food_level"] = {
            f"{food}/{level}": f"scoop success {int(g['scoop_success'].sum())}/{len(g)}, spilled {int(g['spilled_any'].sum())}/{len(g)}"
            for (food, level), g in index.groupby(["food", "level"], sort=True)
        }
    attribution = attribution_summary(index)
    if attribution:
        out["spills_by_stage_and_cause"] = attribution
    summary = manifest.get("summary") or {}
    short = _short_of(summary, out)
    if out["status"] == "complete" and short:
        out["status"] = f"incomplete ({short}; run the same collect command again to regenerate)"
    if "acceptance_rate" in summary:
        out["acceptance_rate"] = summary["acceptance_rate"]
    return out


def chunk_label_rates(index: Any) -> dict[str, Any]:
    """Share of chunks labelled spilled by each label, from the per-episode counts in the index
    (spillage datasets collected with horizon labels): {"chunks": C, "chunk_rate_chunk": ..., "chunk_rate_horizon": ...}."""
    needed = {"n_chunks", "n_chunks_spilled", "n_chunks_spilled_horizon"}
    if not needed <= set(index.columns) or not len(index):
        return {}
    rows = index.dropna(subset=sorted(needed))
    total = int(rows["n_chunks"].sum())
    if total == 0:
        return {}
    return {
        "chunks": total,
        "chunk_rate_chunk": round(float(rows["n_chunks_spilled"].sum()) / total, 3),  # the count rose during the chunk
        "chunk_rate_horizon": round(float(rows["n_chunks_spilled_horizon"].sum()) / total, 3),  # spilled before delivery
    }


def attribution_summary(rows: Any) -> dict[str, str]:
    """Spilled particles summed over `rows` (a DataFrame of records) per stage and cause that has any:
    {"<stage> / <cause>": "<particles> particles (<share>) in <episodes> episodes"}; {} without spills
    or without the `spilled_<stage>_<cause>` columns (grits_lab.sim.spill_metrics)."""
    columns = {c: sc for c, sc in attribution_columns().items() if c in rows.columns}
    if not columns or not len(rows):
        return {}
    counts = rows[list(columns)].fillna(0).astype(int)
    total = int(counts.to_numpy().sum())
    return {f"{stage} / {cause}": f"{int(counts[c].sum())} particles ({counts[c].sum() / total:.0%}) in {int((counts[c] > 0).sum())} episodes"
            for c, (stage, cause) in columns.items() if counts[c].sum() > 0}


def format_summary(summary: dict[str, Any]) -> str:
    lines = []
    for key, value in summary.items():
        if isinstance(value, dict):
            lines.append(f"{key}:")
            lines += [f"  {k:<24} {v}" for k, v in value.items()]
        else:
            lines.append(f"{key:<26} {value}")
    return "\n".join(lines)


def _short_of(recorded: dict[str, Any], found: dict[str, Any]) -> str:
    """What the files on disk lack against the collection's own record of what it wrote ("" if nothing)."""
    targets = recorded.get("targets") or {}
    if targets:  # a balanced spillage dataset: every (shape, label) bucket is full
        have = found.get("by_shape_label", {})
        gaps = [f"{bucket} has {have.get(bucket, 0)} of {int(want)}" for bucket, want in targets.items()
                if have.get(bucket, 0) < int(want)]
        return "; ".join(gaps)
    want = recorded.get("requested")
    if want is not None and found["episodes"] < int(want):
        return f"{found['episodes']} of {int(want)} episodes on disk"
    return ""
