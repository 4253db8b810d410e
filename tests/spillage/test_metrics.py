"""AUROC and calibration error against direct definitions."""

from __future__ import annotations

import numpy as np

from grits_lab.spillage.classifier_metrics import accuracy, auroc, expected_calibration_error


def test_auroc_matches_pair_counting_with_ties():
    rng = np.random.default_rng(0)
    p = np.round(rng.uniform(size=200), 1)  # many ties
    y = rng.uniform(size=200) < p
    pos, neg = p[y], p[~y]
    pairs = (pos[:, None] > neg[None, :]).mean() + 0.5 * (pos[:, None] == neg[None, :]).mean()
    assert abs(auroc(p, y) - pairs) < 1e-12
    assert auroc(np.array([0.1, 0.9]), np.array([0, 1])) == 1.0
    assert np.isnan(auroc(np.array([0.1, 0.9]), np.array([1, 1])))


def test_ece_is_small_for_calibrated_and_large_for_overconfident_predictions():
    rng = np.random.default_rng(1)
    p = rng.uniform(size=100_000)
    y = rng.uniform(size=p.size) < p
    assert expected_calibration_error(p, y) < 0.01
    overconfident = np.where(p > 0.5, 1.0, 0.0)
    assert expected_calibration_error(overconfident, y) > 0.2
    assert accuracy(np.array([0.2, 0.7, 0.5]), np.array([0, 1, 0])) == 2 / 3


def test_a_predictor_at_chance_or_with_flat_outputs_is_called_degenerate():
    from grits_lab.spillage.classifier_metrics import degenerate_reason

    assert degenerate_reason(0.52, 0.2) == "its validation AUROC is 0.52, chance level"
    assert "barely varies" in degenerate_reason(0.87, 0.004)  # ranks well, but guidance has no gradient to follow
    assert "undefined" in degenerate_reason(float("nan"), 0.2)
    assert degenerate_reason(0.8, 0.2) is None
    assert degenerate_reason(0.3, 0.2) is None  # ranks backwards: wrong, but not flat
