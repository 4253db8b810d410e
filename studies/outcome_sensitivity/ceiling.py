"""How well any predictor could rank an outcome that a sub-millimetre nudge changes: the AUROC ceiling.

Two runs on the same seeds, the second with every scoop action offset by a distance no observation
resolves (the nudge, studies/outcome_sensitivity/hooks.py), give each episode two
draws of a binary outcome y from the same observations. Take an episode's outcome as a coin with
its own chance p of coming up 1, the pair as two tosses of that coin. Then

    rate  m = E[p]            = the outcome's rate over both runs,
    noise v = E[p (1 - p)]    = half the fraction of episodes whose two outcomes differ,

and the best score any predictor of those observations can give an episode is p itself. Its AUROC
against the outcome is

    AUROC(p) = E[p_a (1 - p_b) (1[p_a > p_b] + 1/2 1[p_a = p_b])] / (m (1 - m)),

a and b two episodes drawn independently. `max_auroc` is the largest value this takes over every
distribution of p on [0, 1] with the measured m and v: no predictor that sees what both runs of an
episode share can rank the outcome better on such episodes. v = 0 (the nudge changes nothing)
allows 1; v = m (1 - m) (every episode a coin of chance m) forces 0.5.

The maximum is a quadratic programme over the weights of a grid of values of p (non-convex: solved
from several random starts with SLSQP). `repeatability` estimates m and v from the paired episodes
and the ceiling with a 95 % interval from resampling episodes.
"""

from __future__ import annotations

import functools

import numpy as np
import pandas as pd

from grits_lab.report.run_compare import CEILING_OUTCOMES


def max_auroc(rate: float, noise: float, *, grid: int = 21, starts: int = 4, seed: int = 0) -> float:
    """The largest AUROC of any score against a binary outcome of mean `rate` (m, in (0, 1)) whose
    chance part is `noise` (v = E[p (1 - p)], >= 0), over distributions of p on a grid of `grid`
    values in [0, 1] with m added; v above m (1 - m), which no distribution reaches, is taken as
    m (1 - m). NaN for a rate of 0 or 1 (nothing to rank). Deterministic for a given `seed`, and
    remembered per argument tuple (a bootstrap of paired episodes meets the same (m, v) often)."""
    if not 0.0 < rate < 1.0:
        return float("nan")
    return _max_auroc(float(rate), min(max(float(noise), 0.0), rate * (1.0 - rate)), grid, starts, seed)


@functools.lru_cache(maxsize=4096)
def _max_auroc(rate: float, noise: float, grid: int, starts: int, seed: int) -> float:
    from scipy.optimize import minimize

    p = np.unique(np.append(np.linspace(0.0, 1.0, grid), rate))
    wins = np.outer(p, 1.0 - p) * ((p[:, None] > p[None, :]) + 0.5 * np.eye(len(p)))
    sym = wins + wins.T
    ones, spread = np.ones_like(p), p * (1.0 - p)
    constraints = [{"type": "eq", "fun": lambda w: w.sum() - 1.0, "jac": lambda w: ones},
                   {"type": "eq", "fun": lambda w: w @ p - rate, "jac": lambda w: p},
                   {"type": "eq", "fun": lambda w: w @ spread - noise, "jac": lambda w: spread}]
    rng = np.random.default_rng(seed)
    best = 0.5 if np.isclose(noise, rate * (1.0 - rate)) else 0.0
    for _ in range(starts):
        result = minimize(lambda w: -(w @ wins @ w), rng.dirichlet(np.ones(len(p))), jac=lambda w: -(sym @ w),
                          bounds=[(0.0, 1.0)] * len(p), constraints=constraints, method="SLSQP", options={"maxiter": 500})
        if result.success:
            best = max(best, float(-result.fun) / (rate * (1.0 - rate)))
    return min(best, 1.0)


def rate_and_noise(before: np.ndarray, after: np.ndarray) -> tuple[float, float]:
    """(m, v) of paired binary outcomes (N,) each: the mean over both runs and half the discordant fraction."""
    before, after = np.asarray(before, dtype=bool), np.asarray(after, dtype=bool)
    return float((before.mean() + after.mean()) / 2.0), float((before != after).mean() / 2.0)


def repeatability(pairs: pd.DataFrame, *, outcomes: tuple[str, ...] = CEILING_OUTCOMES, n_bootstrap: int = 200,
                  seed: int = 0) -> pd.DataFrame:
    """Per method and outcome of `pairs` (run_compare.paired_episodes' columns `<outcome>_before` /
    `_after`, errors already left out): the paired episodes, the outcome's rate over both runs, the
    fraction of episodes whose outcome differs, and the AUROC ceiling (`max_auroc`) with the 2.5 and
    97.5 percentiles over `n_bootstrap` resamples of the episodes. Outcomes the pairs lack are skipped."""
    rng = np.random.default_rng(seed)
    rows = []
    for method in dict.fromkeys(pairs["method"]):
        group = pairs[pairs["method"] == method]
        for outcome in outcomes:
            if f"{outcome}_before" not in group.columns:
                continue
            a, b = group[f"{outcome}_before"].to_numpy(bool), group[f"{outcome}_after"].to_numpy(bool)
            rate, noise = rate_and_noise(a, b)
            resampled = []
            for _ in range(n_bootstrap):
                index = rng.integers(0, len(a), len(a))
                resampled.append(max_auroc(*rate_and_noise(a[index], b[index])))
            finite = [x for x in resampled if not np.isnan(x)]
            low, high = np.percentile(finite, [2.5, 97.5]) if finite else (np.nan, np.nan)
            rows.append({"method": method, "outcome": outcome, "paired": int(len(a)), "rate": rate,
                         "changed": int((a != b).sum()), "changed_fraction": float((a != b).mean()),
                         "auroc_ceiling": max_auroc(rate, noise), "auroc_ceiling_low": float(low), "auroc_ceiling_high": float(high)})
    return pd.DataFrame(rows)


def ceiling_columns(declared: bool = False):
    """The `per_method` callable of grits_lab.report.run_compare.compare_runs that adds each outcome's
    AUROC ceiling (`repeatability`) to a method's row when its runs differ by a nudge (offset or
    draw), when every pair ran on other CPU kernels, or always with `declared` (the caller declares
    the runs two draws of one chance that the records do not name): each outcome's changes are then
    its chance part. The row gets `ceiling_declared` either way."""

    def columns(pairs: pd.DataFrame, row: dict) -> dict:
        out: dict = {"ceiling_declared": bool(declared)}
        nudged_apart = (row["action_offset_before_m"] != row["action_offset_after_m"]
                        or row["action_offset_before_m"] > 0 and row["action_offset_draw_before"] != row["action_offset_draw_after"])
        if len(pairs) and (nudged_apart or row["kernels_differ"] == len(pairs) or declared):
            for _, c in repeatability(pairs).iterrows():
                out.update({f"{c['outcome']}_{k}": c[k] for k in ("auroc_ceiling", "auroc_ceiling_low", "auroc_ceiling_high")})
        return out

    return columns
