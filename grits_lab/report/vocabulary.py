"""The report's fixed vocabulary: method and food display names, orders, and the paper's numbers.

Everything a reader compares across reports (names, abbreviations, the order of rows, the
real-robot numbers of the paper) is defined once here so that every table and figure agrees.
"""

from __future__ import annotations

from grits_lab.records import UNSEEN_FOODS
from grits_lab.report.real_trials import canonical_name, paper_rates  # noqa: F401 (canonical_name: re-exported)

METHOD_NAMES: dict[str, str] = {
    "expert": "Scripted expert (oracle)",
    "rule_based": "Rule-based",
    "bc": "Behavior cloning",
    "scone": "SCONE",
    "dp": "Diffusion Policy",
    "dp_post": "Diffusion Policy (Post.)",
    "grits": "GRITS",
    "grits_raw": "GRITS (raw cloud)",
    "grits_pointnet2": "GRITS (PointNet++)",
    "grits_horizon": "GRITS (horizon labels)",
}

# The paper's guidance weight and threshold (SPEC), the setting tuned points are measured against.
PAPER_DEFAULTS = {"rho": 2.5, "s": 30}


def at_paper_defaults(rho: "pd.Series", s: "pd.Series") -> "pd.Series":
    """Per row: is (rho, s) the paper's setting (`PAPER_DEFAULTS`; rho compared with np.isclose)."""
    import numpy as np
    import pandas as pd

    return pd.Series(np.isclose(pd.to_numeric(rho, errors="coerce"), PAPER_DEFAULTS["rho"]), index=rho.index) & (s == PAPER_DEFAULTS["s"])

# Paper Fig. 5 compares these methods, in this order.
MAIN_METHODS = ("rule_based", "bc", "scone", "dp", "dp_post", "grits")
# Paper Fig. 8: the predictor ablation, weakest variant first as in the paper's caption.
ABLATION_METHODS = ("grits_raw", "grits_pointnet2", "grits")
# Paper Fig. 6: vanilla diffusion policy (left) against GRITS (right).
PER_FOOD_METHODS = ("dp", "grits")

# The ten unseen test foods (grits_lab/records.py, the paper's order) with the abbreviations of its Fig. 6.
FOOD_ABBREVIATIONS: dict[str, str] = dict(zip(UNSEEN_FOODS, ("SA", "RB", "MT", "MM", "FD", "PE", "PR", "RS", "NU", "MK")))

LEVEL_ORDER = ("low", "medium", "high")

OUTCOME_NAMES: dict[str, str] = {
    "task_success": "Task success",
    "spillage": "Spillage",
    "scoop_failure": "Scoop failure",
}

# Real-robot results of the paper (SPEC.md, "Headline results"): fraction of trials, over
# 10 unseen foods x 2 levels x 5 trials = 100 trials per method. Only numbers the paper states,
# read from the real-trials file that ships them (grits_lab/report/paper_real_robot.csv).
PAPER_RESULTS: dict[str, dict[str, float]] = paper_rates()
PAPER_TRIALS_PER_METHOD = 100
# "GRITS reduces spillage by more than 40% relative to diffusion policy without guidance."
PAPER_SPILLAGE_REDUCTION_VS_DP = 0.40

SIM_LABEL = "simulation"
PAPER_LABEL = "real robot (paper)"
MISSING = "—"




def method_display(method: str) -> str:
    return METHOD_NAMES.get(method, method)


def food_display(food: str, long: bool = False) -> str:
    """`SA` (or `SA sago` with long=True) for a paper food; the record's own name otherwise."""
    abbreviation = FOOD_ABBREVIATIONS.get(canonical_name(food))
    if abbreviation is None:
        return str(food)
    return f"{abbreviation} {canonical_name(food).replace('_', ' ')}" if long else abbreviation


def ordered(values: object, preferred: tuple[str, ...]) -> list[str]:
    """`values` with those in `preferred` first (in that order), the rest sorted after them."""
    present = {str(v) for v in values}
    head = [v for v in dict.fromkeys(preferred) if v in present]
    return head + sorted(present - set(head))
