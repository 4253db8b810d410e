"""The AUROC ceiling of an outcome whose chance part a nudge reveals (studies/outcome_sensitivity/ceiling.py)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from studies.outcome_sensitivity.ceiling import max_auroc, rate_and_noise, repeatability


def _auroc_of_mix(values: np.ndarray, weights: np.ndarray) -> float:
    """AUROC of the score p against outcomes drawn from it, for a mix of coins (exact, ties counted half)."""
    rate = weights @ values
    total = 0.0
    for i, (pa, wa) in enumerate(zip(values, weights)):
        for j, (pb, wb) in enumerate(zip(values, weights)):
            total += wa * wb * pa * (1 - pb) * (1.0 if pa > pb else 0.5 if i == j else 0.0)
    return total / (rate * (1 - rate))


def test_an_outcome_the_nudge_never_changes_can_be_ranked_perfectly_and_a_fair_coin_not_at_all():
    assert max_auroc(0.3, 0.0) == pytest.approx(1.0, abs=1e-6)
    assert max_auroc(0.3, 0.3 * 0.7) == pytest.approx(0.5, abs=1e-6)
    assert max_auroc(0.3, 0.5) == pytest.approx(0.5, abs=1e-6)  # beyond what any mix reaches: every episode a coin of 0.3
    assert math.isnan(max_auroc(0.0, 0.0)) and math.isnan(max_auroc(1.0, 0.0))


def test_the_ceiling_falls_as_the_nudge_changes_more_and_bounds_every_mix_with_those_moments():
    ceilings = [max_auroc(0.35, v) for v in (0.02, 0.06, 0.10, 0.15, 0.20)]
    assert all(a > b for a, b in zip(ceilings, ceilings[1:]))
    # a mix of coins on the grid: 40 % never, 30 % half the time, 30 % always
    values, weights = np.array([0.0, 0.5, 1.0]), np.array([0.4, 0.3, 0.3])
    rate, noise = weights @ values, weights @ (values * (1 - values))
    own = _auroc_of_mix(values, weights)
    assert own == pytest.approx((0.3 * (0.4 + 0.15) + 0.15 * 0.4 + 0.5 * 0.15 * 0.15) / (rate * (1 - rate)))
    assert own <= max_auroc(rate, noise) + 1e-6
    # and no mix with those moments does better than the ceiling: random mixes on a finer grid
    rng = np.random.default_rng(1)
    grid = np.linspace(0, 1, 11)
    for _ in range(60):
        w = rng.dirichlet(np.ones(11) * 0.3)
        m, v = w @ grid, w @ (grid * (1 - grid))
        if 0.05 < m < 0.95:
            assert _auroc_of_mix(grid, w) <= max_auroc(m, v, grid=41, starts=8) + 1e-3


def test_paired_outcomes_give_the_rate_over_both_runs_and_half_the_changed_fraction():
    before = np.array([1, 1, 0, 0, 1, 0, 0, 0], dtype=bool)
    after = np.array([1, 0, 1, 0, 1, 0, 0, 0], dtype=bool)
    assert rate_and_noise(before, after) == (pytest.approx(6 / 16), pytest.approx(2 / 8 / 2))  # 3 + 3 of 16; 2 of 8 changed


def test_repeatability_reports_each_outcome_with_an_interval_around_its_ceiling():
    rng = np.random.default_rng(0)
    coin = rng.choice([0.0, 0.5, 1.0], size=60, p=[0.5, 0.3, 0.2])
    pairs = pd.DataFrame({"method": "dp", "spillage_before": rng.random(60) < coin, "spillage_after": rng.random(60) < coin})
    table = repeatability(pairs, outcomes=("spillage", "task_success"), n_bootstrap=40)
    assert list(table["outcome"]) == ["spillage"]  # the pairs hold no task success
    row = table.iloc[0]
    assert row["paired"] == 60 and row["changed"] == int((pairs["spillage_before"] != pairs["spillage_after"]).sum())
    assert row["auroc_ceiling_low"] <= row["auroc_ceiling"] <= row["auroc_ceiling_high"] <= 1.0
    assert 0.5 < row["auroc_ceiling"] < 1.0
