"""The spillage predictor as its training run left it: validation and held-out scores, calibration, and whether it can steer.

Read from a predictor run directory (grits_lab/spillage/predictor_training.py): `history.json` (one
row per epoch), `config.yaml` (the label, the class weighting and the metric that chose `best.pt`)
and, where the pipeline scored the predictor on held-back trials, `heldout.json`
(`evaluate_predictor`). Needs no torch: the report reads files only.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import yaml

from grits_lab.spillage.classifier_metrics import degenerate_reason

HELDOUT_FILE = "heldout.json"


@dataclass(frozen=True)
class PredictorQuality:
    """One predictor run: its checkpoint epoch's validation scores, held-out scores (or None) and
    `degenerate`, why it cannot steer guidance (None when it can)."""

    name: str
    run_dir: Path
    label: str
    class_weight: str
    best: dict[str, Any]
    heldout: dict[str, Any] | None
    degenerate: str | None

    def line(self) -> str:
        """One sentence: validation and held-out AUROC with the chunk counts, and the calibration line."""
        b = self.best
        text = (f"Predictor `{self.name}` (label {self.label}, class weight {self.class_weight}): validation AUROC "
                f"{b.get('val_auroc', math.nan):.2f} on {b.get('val_n', 0)} chunks ({_positives(b, 'val_')} spilling)")
        if self.heldout is not None:
            h = self.heldout
            text += (f"; held-out AUROC {h['auroc']:.2f} on {h['n']} chunks of held-back trials ({_positives(h, '')} spilling). "
                     f"Calibration on them: mean P(spill) {h.get('mean_p_spill', math.nan):.2f} against a spill rate of "
                     f"{h['spill_rate']:.2f}, ECE {h['ece']:.3f}")
        else:
            text += f"; calibration on validation: ECE {b.get('val_ece', math.nan):.3f}, spill rate {b.get('val_spill_rate', math.nan):.2f}"
        if self.class_weight == "balanced":
            text += " (class-weighted training calibrates P(spill) to a 50 % prior, not to these rates)"
        return text + "." + (f" Degenerate: {self.degenerate}." if self.degenerate else "")


def _positives(row: dict[str, Any], prefix: str) -> str:
    if f"{prefix}positives" in row:
        return str(int(row[f"{prefix}positives"]))
    n, share = row.get(f"{prefix}n"), row.get(f"{prefix}spill_rate")
    return str(round(n * share)) if n is not None and share is not None and math.isfinite(share) else "?"


def read_predictor(run_dir: str | Path) -> PredictorQuality | None:
    """The quality of the predictor run in `run_dir`, or None where it holds no history.json."""
    run_dir = Path(run_dir)
    try:
        history = json.loads((run_dir / "history.json").read_text())
    except (OSError, ValueError):
        return None
    if not history:
        return None
    config = yaml.safe_load((run_dir / "config.yaml").read_text()) if (run_dir / "config.yaml").is_file() else {}
    train, data = (config or {}).get("train", {}), (config or {}).get("data", {})
    by_auroc = train.get("select_metric") == "val_auroc"
    best = min(history, key=lambda r: -r["val_auroc"] if by_auroc else r["val_loss"])
    heldout = None
    if (run_dir / HELDOUT_FILE).is_file():
        heldout = json.loads((run_dir / HELDOUT_FILE).read_text())
    spread = best.get("val_p_spill_std")
    reason = degenerate_reason(float(best.get("val_auroc", math.nan)), float(spread)) if spread is not None else None
    return PredictorQuality(run_dir.name, run_dir, str(data.get("label", "chunk")), str(train.get("class_weight", "none")),
                            best, heldout, reason)


def find_predictors(dirs: Sequence[str | Path]) -> list[PredictorQuality]:
    """Every predictor run in `dirs` (each a run directory or a folder of them, one level deep)."""
    found = []
    for root in map(Path, dirs):
        for candidate in [root, *sorted(p for p in root.glob("*") if p.is_dir())] if root.is_dir() else []:
            if (quality := read_predictor(candidate)) is not None:
                found.append(quality)
    return found
