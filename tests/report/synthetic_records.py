"""Synthetic evaluation records with the columns of grits_lab/records.py, for the report tests.

`episode` writes one record with explicit outcomes, so every table value in the tests can be
counted by hand; `plausible_run` draws a full methods x foods x levels x trials run from fixed
per-method outcome probabilities, for looking at the figures of a realistic report.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from grits_lab.records import RECORD_COLUMNS
from grits_lab.report.vocabulary import UNSEEN_FOODS
from grits_lab.seeding import derive_seed
from grits_lab.versions import PROTOCOL


def episode(method: str, food: str, level: str, trial: int, outcome: str, *, spilled_before_scoop: bool | None = None,
            error: str = "", rho: float = math.nan, s: int = -1, run_id: str = "synthetic", protocol: str = PROTOCOL) -> dict:
    """One record; `outcome` is one of success, spill, scoop_fail, spill_and_scoop_fail, transfer_fail."""
    success = outcome == "success"
    spill = outcome in ("spill", "spill_and_scoop_fail")
    scoop_fail = outcome in ("scoop_fail", "spill_and_scoop_fail")
    if method in ("grits", "grits_raw", "grits_pointnet2", "dp_post") and math.isnan(rho):
        rho, s = 2.5, 30
    row = {
        "run_id": run_id, "protocol": protocol, "method": method, "food": food, "split": "unseen", "level": level, "trial": trial,
        "seed": derive_seed(0, food, level, trial),
        "task_success": success and not error, "spillage": spill, "scoop_failure": scoop_fail,
        "scoop_success": not scoop_fail, "spilled_before_scoop": spill if spilled_before_scoop is None else spilled_before_scoop,
        "n_particles": 160, "spilled": 7 if spill else 0, "scooped": 0 if scoop_fail else 20,
        "transferred": 20 if success else 0, "rho": rho, "s": s, "error": error, "wall_time_s": 12.5,
    }
    assert set(row) == set(RECORD_COLUMNS)
    return row


def plausible_run(seed: int = 0, skip: dict[str, list[str]] | None = None) -> pd.DataFrame:
    """Every paper method x 10 foods x 2 levels x 5 trials, outcomes drawn from fixed probabilities."""
    probabilities = {  # success, spill, scoop failure, transfer failure (rest of the mass)
        "rule_based": (0.30, 0.35, 0.30), "bc": (0.45, 0.35, 0.15), "scone": (0.60, 0.15, 0.22),
        "dp": (0.70, 0.20, 0.08), "dp_post": (0.48, 0.08, 0.40), "grits": (0.80, 0.05, 0.13),
        "grits_raw": (0.62, 0.16, 0.18), "grits_pointnet2": (0.66, 0.13, 0.17),
    }
    skip = skip or {}
    rng = np.random.default_rng(seed)
    rows = []
    for method, (p_success, p_spill, p_fail) in probabilities.items():
        for food in UNSEEN_FOODS:
            if food in skip.get(method, []):
                continue
            for level in ("low", "high"):
                for trial in range(5):
                    u = rng.random()
                    outcome = ("success" if u < p_success else "spill" if u < p_success + p_spill
                               else "scoop_fail" if u < p_success + p_spill + p_fail else "transfer_fail")
                    early = outcome == "spill" or (outcome == "scoop_fail" and rng.random() < 0.3)
                    error = "IK failed to converge" if rng.random() < 0.01 else ""
                    rows.append(episode(method, food, level, trial, outcome, spilled_before_scoop=early, error=error))
    return pd.DataFrame(rows)
