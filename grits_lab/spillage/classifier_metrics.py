"""Binary-classifier metrics of the predictor: accuracy, AUROC and expected calibration error.

Guidance follows the gradient of P(spill), so how well that probability is calibrated matters as
much as how well it ranks; ECE is measured on P(spill) itself (reliability of the spill class).
"""

from __future__ import annotations

import numpy as np


def accuracy(prob_spill: np.ndarray, labels: np.ndarray, threshold: float = 0.5) -> float:
    prob_spill, labels = _check(prob_spill, labels)
    return float(np.mean((prob_spill >= threshold) == labels.astype(bool)))


def auroc(prob_spill: np.ndarray, labels: np.ndarray) -> float:
    """Area under the ROC curve by the rank (Mann-Whitney) statistic, ties counted half; NaN if one class is absent."""
    prob_spill, labels = _check(prob_spill, labels)
    pos = labels.astype(bool)
    n_pos, n_neg = int(pos.sum()), int((~pos).sum())
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    order = np.argsort(prob_spill, kind="mergesort")
    sorted_scores = prob_spill[order]
    ranks = np.empty(len(prob_spill), dtype=np.float64)
    # average ranks over ties
    _, first, counts = np.unique(sorted_scores, return_index=True, return_counts=True)
    avg = first + (counts - 1) / 2.0 + 1.0
    ranks[order] = np.repeat(avg, counts)
    return float((ranks[pos].sum() - n_pos * (n_pos + 1) / 2.0) / (n_pos * n_neg))


def auroc_within(prob_spill: np.ndarray, labels: np.ndarray, strata: np.ndarray) -> float:
    """AUROC over the (spill, no-spill) pairs of the same stratum only (a stratified Mann-Whitney
    statistic): sum_g AUROC_g * n_pos_g * n_neg_g / sum_g n_pos_g * n_neg_g; NaN if no stratum holds
    both classes.

    With strata = foods it asks whether a predictor tells a spilling chunk from a safe one of the same
    food, which is what guidance needs; the pooled AUROC also credits knowing which foods spill more.
    """
    prob_spill, labels = _check(prob_spill, labels)
    strata = np.asarray(strata).reshape(-1)
    if strata.shape != labels.shape:
        raise ValueError(f"strata {strata.shape} and labels {labels.shape} differ in length")
    weighted, pairs = 0.0, 0
    for g in np.unique(strata):
        at = strata == g
        n_pos = int(labels[at].sum())
        n_pairs = n_pos * (int(at.sum()) - n_pos)
        if n_pairs:
            weighted += auroc(prob_spill[at], labels[at]) * n_pairs
            pairs += n_pairs
    return float(weighted / pairs) if pairs else float("nan")


def reliability_bins(prob_spill: np.ndarray, labels: np.ndarray, n_bins: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per non-empty equal-width bin of P(spill): mean P(spill), spill rate and sample count."""
    prob_spill, labels = _check(prob_spill, labels)
    bins = np.clip((prob_spill * n_bins).astype(int), 0, n_bins - 1)
    filled = [b for b in range(n_bins) if (bins == b).any()]
    mean_p = np.array([prob_spill[bins == b].mean() for b in filled])
    rate = np.array([labels[bins == b].mean() for b in filled])
    count = np.array([int((bins == b).sum()) for b in filled])
    return mean_p, rate, count


def expected_calibration_error(prob_spill: np.ndarray, labels: np.ndarray, n_bins: int = 10) -> float:
    """sum_b |B_b|/n * |mean P(spill) in b - spill rate in b| over equal-width bins of P(spill)."""
    mean_p, rate, count = reliability_bins(prob_spill, labels, n_bins)
    if count.sum() == 0:
        return float("nan")
    return float(np.sum(count * np.abs(mean_p - rate)) / count.sum())


def classification_report(prob_spill: np.ndarray, labels: np.ndarray, n_bins: int = 10) -> dict[str, float]:
    prob_spill, labels = _check(prob_spill, labels)
    return {
        "accuracy": accuracy(prob_spill, labels),
        "auroc": auroc(prob_spill, labels),
        "ece": expected_calibration_error(prob_spill, labels, n_bins),
        "n": int(len(labels)),
        "spill_rate": float(labels.mean()) if len(labels) else float("nan"),
        "positives": int(labels.sum()),
        "p_spill_std": float(np.std(prob_spill)) if len(labels) else float("nan"),
    }


def _check(prob_spill: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(prob_spill, dtype=np.float64).reshape(-1)
    y = np.asarray(labels, dtype=np.float64).reshape(-1)
    if p.shape != y.shape:
        raise ValueError(f"probabilities {p.shape} and labels {y.shape} differ in length")
    return p, y


METRICS = {"auroc": auroc, "accuracy": accuracy}


def paired_bootstrap(
    probs: dict[str, np.ndarray],
    labels: np.ndarray,
    groups: np.ndarray,
    n_resamples: int = 2000,
    seed: int = 0,
    metrics: tuple[str, ...] = ("auroc", "accuracy"),
    strata: np.ndarray | dict[str, np.ndarray] | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """Each metric of each model on the same `n_resamples` resamples of whole groups (episodes).

    Chunks of one episode share its food and its start, so they are not independent: resampling
    episodes, not chunks, gives honest intervals, and scoring every model on the same resample
    makes the differences between models paired (their common noise cancels). Returns
    `{metric: {model: (n_resamples,) values}}`; a resample with one class only gives NaN AUROC.
    A metric named "auroc_within..." is auroc_within over its strata, one per sample: `strata` is
    either one array (for "auroc_within", e.g. each chunk's food) or `{metric: array}`.
    """
    labels = np.asarray(labels).reshape(-1)
    groups = np.asarray(groups).reshape(-1)
    probs = {name: np.asarray(p, dtype=np.float64) for name, p in probs.items()}
    for name, p in probs.items():
        if p.shape != labels.shape:
            raise ValueError(f"model {name!r}: {p.shape} probabilities for {labels.shape} labels")
    by_metric = {} if strata is None else strata if isinstance(strata, dict) else {"auroc_within": strata}
    by_metric = {m: np.asarray(v).reshape(-1) for m, v in by_metric.items()}
    for m in metrics:
        if m.startswith("auroc_within") and (m not in by_metric or by_metric[m].shape != labels.shape):
            raise ValueError(f"the metric {m} needs one stratum per label")
    _, group_of = np.unique(groups, return_inverse=True)
    members = [np.flatnonzero(group_of == g) for g in range(group_of.max() + 1)] if len(groups) else []
    rng = np.random.default_rng(seed)
    out = {m: {name: np.empty(n_resamples) for name in probs} for m in metrics}
    for r in range(n_resamples):
        idx = np.concatenate([members[g] for g in rng.integers(len(members), size=len(members))])
        for name, p in probs.items():
            for m in metrics:
                out[m][name][r] = (auroc_within(p[idx], labels[idx], by_metric[m][idx]) if m.startswith("auroc_within")
                                   else METRICS[m](p[idx], labels[idx]))
    return out


# A predictor whose validation AUROC lies this close to 0.5, or whose P(spill) varies less than this
# (standard deviation across chunks), gives guidance no direction: its gradient steers at random or not at all.
DEGENERATE_AUROC_MARGIN = 0.05
DEGENERATE_SPREAD = 0.01


def degenerate_reason(val_auroc: float, spread: float) -> str | None:
    """Why a predictor cannot steer guidance, in words, or None when it can.

    val_auroc: its validation AUROC (NaN when a class is missing); spread: the standard deviation of
    its P(spill) across the validation chunks (`p_spill_std` of classification_report). Degenerate:
    AUROC undefined or within DEGENERATE_AUROC_MARGIN of 0.5, or a spread below DEGENERATE_SPREAD.
    """
    if not np.isfinite(val_auroc):
        return "its validation AUROC is undefined (one class has no chunk)"
    if abs(val_auroc - 0.5) < DEGENERATE_AUROC_MARGIN:
        return f"its validation AUROC is {val_auroc:.2f}, chance level"
    if spread < DEGENERATE_SPREAD:
        return f"its P(spill) barely varies across chunks (standard deviation {spread:.4f})"
    return None
