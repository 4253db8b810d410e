"""Held-out comparison of trained spillage predictors, with paired episode-bootstrap intervals.

The question the predictor's evidence has to answer is not "how good is each model" but "does
the full model beat the ablations and the baselines on data it never saw", so every model is
scored on the same chunks, the intervals come from resampling whole episodes, and each model's
difference to the reference (the first one) is computed on the same resamples.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from grits_lab.errors import InputError
from grits_lab.io import atomic_path, ensure_writable_dir, save_parquet_atomic, write_json_atomic, write_text_atomic
from grits_lab.markdown import markdown_table
from grits_lab.spillage.classifier_metrics import auroc_within, classification_report, paired_bootstrap, reliability_bins

# Scores without a model, ranked beside the predictors: a predictor that guidance can use must beat
# what it cannot change. Under the horizon label a chunk early in its scoop has more of the task
# ahead of it, so it spills more often whatever its trajectory.
BASELINES = {
    "chunk_position": "no model: 1 / (1 + the chunk's index in its episode), earlier chunks ranked higher",
}

LABEL_MEANING = {
    "chunk": "the spilled count rose during the chunk's own actions",
    "horizon": "food spilled from the chunk's first action until the load was delivered",
}


def baseline_scores(predictions: pd.DataFrame) -> dict[str, np.ndarray]:
    """Each baseline's score per chunk, `{name: (n_chunks,) float}` in (0, 1]: rank-only, not a
    probability (their accuracy and ECE are not reported). Empty without a `chunk` column."""
    if "chunk" not in predictions.columns:
        return {}
    return {"chunk_position": 1.0 / (1.0 + predictions["chunk"].to_numpy(dtype=np.float64))}


@dataclass
class Comparison:
    table: pd.DataFrame  # one row per model, then per baseline (`kind`): metrics, intervals, difference to the reference
    predictions: pd.DataFrame  # one row per chunk: episode, chunk, label, p_<model>...
    reference: str
    n_resamples: int
    n_bins: int = 10  # reliability bins, as for the ECE in the table
    label: str = "chunk"  # what the `label` column says: "chunk" or "horizon" (grits_lab/data/chunk_labels.py)
    label_meaning: str | None = None  # in words, where LABEL_MEANING's does not hold (a horizon that ends with the scoop)


def compare_predictions(predictions: pd.DataFrame, models: list[str], n_resamples: int = 2000, seed: int = 0, n_bins: int = 10,
                        label: str = "chunk", baselines: bool | None = None) -> Comparison:
    """Table of AUROC / accuracy / ECE with 95 % intervals and paired differences to `models[0]`;
    with `baselines` (default: under the horizon label, whose spills fall early in an episode), the
    rows of BASELINES follow the models (AUROC only, on the same resamples)."""
    if not models:
        raise InputError("no predictors to compare")
    labels = predictions["label"].to_numpy()
    probs = {m: predictions[f"p_{m}"].to_numpy() for m in models}
    extra = baseline_scores(predictions) if (label == "horizon" if baselines is None else baselines) else {}
    if clash := set(extra) & set(models):
        raise InputError(f"a predictor is named like a baseline ({', '.join(sorted(clash))}); rename it")
    probs.update(extra)
    strata = within_strata(predictions)
    metrics = ("auroc", "accuracy", *strata)
    boot = paired_bootstrap(probs, labels, predictions["episode"].to_numpy(), n_resamples=n_resamples, seed=seed,
                            metrics=metrics, strata=strata)
    reference = models[0]
    point = {m: classification_report(probs[m], labels, n_bins) for m in probs}
    for m in extra:  # a rank is not a probability: no accuracy, no calibration
        point[m].update(accuracy=float("nan"), ece=float("nan"))
        boot["accuracy"][m] = np.full(n_resamples, np.nan)
    for metric, groups in strata.items():
        for m in probs:
            point[m][metric] = auroc_within(probs[m], labels, groups)
    rows = []
    for m in probs:
        row: dict[str, Any] = {"model": m, "kind": "baseline" if m in extra else "model", **point[m]}
        if m not in extra and "chunk" in predictions.columns and predictions["chunk"].nunique() > 1:
            row["spearman_position"] = spearman_with_position(probs[m], predictions)
        for metric in metrics:
            row[f"{metric}_lo"], row[f"{metric}_hi"] = _interval(boot[metric][m])
            if m == reference:
                continue
            key = f"{reference}_minus_{metric}"
            diff = boot[metric][reference] - boot[metric][m]
            diff = diff[~np.isnan(diff)]
            row[key] = point[reference][metric] - point[m][metric]
            row[f"{key}_lo"], row[f"{key}_hi"] = _interval(diff)
            row[f"{key}_p"] = float(np.mean(diff <= 0)) if len(diff) else float("nan")  # share of resamples where the reference is not better
        rows.append(row)
    return Comparison(pd.DataFrame(rows), predictions, reference, n_resamples, n_bins, label)


def strata_column(predictions: pd.DataFrame) -> str | None:
    """The column the within-food AUROC stratifies by ("food" or "shape", as predict_chunks writes
    it), or None when the chunks hold neither or only one value of it."""
    for column in ("food", "shape"):
        if column in predictions.columns and predictions[column].nunique() > 1:
            return column
    return None


def _food_per_chunk(predictions: pd.DataFrame) -> np.ndarray:
    """Each chunk's food (or shape) as text, the column strata_column names; "" for every chunk when
    the chunks are of one food."""
    stratum = strata_column(predictions)
    return np.full(len(predictions), "", dtype=object) if stratum is None else predictions[stratum].astype(str).to_numpy()


def within_strata(predictions: pd.DataFrame) -> dict[str, np.ndarray]:
    """The strata of the stratified AUROCs the chunks allow, `{metric: (n_chunks,) labels}`:
    "auroc_within" by food (strata_column), and "auroc_within_position" by food and the chunk's
    index in its episode (by the index alone when the chunks are of one food; absent when every
    chunk has one index), which asks what guidance needs: of the chunks of one food at one point of
    the scoop, does the predictor rank those that spill higher? Any score of the position alone is
    0.5 there. With a `state` column (a branch study), "auroc_within_state": over the pairs of the
    policy's samples from one and the same state, the choice guidance makes."""
    out: dict[str, np.ndarray] = {}
    food = _food_per_chunk(predictions)
    if strata_column(predictions) is not None:
        out["auroc_within"] = food
    if "chunk" in predictions.columns and predictions["chunk"].nunique() > 1:
        out["auroc_within_position"] = np.asarray([f"{f}#{c}" for f, c in zip(food, predictions["chunk"].to_numpy())])
    if "state" in predictions.columns:  # a branch study's draws (studies/outcome_sensitivity/branches.py)
        out["auroc_within_state"] = predictions["state"].astype(str).to_numpy()
    return out


def spearman_with_position(scores: np.ndarray, predictions: pd.DataFrame) -> float:
    """Spearman correlation of a model's P(spill) with the chunk's index in its episode, within each
    food (strata_column) and averaged weighted by its chunks; NaN where no food varies in both. Near
    -1, the model's score is mostly how early in the scoop a chunk is, and the gradient guidance
    follows points toward what later chunks look like."""
    frame = pd.DataFrame({"p": np.asarray(scores, dtype=np.float64), "chunk": predictions["chunk"].to_numpy(),
                          "food": _food_per_chunk(predictions)})
    total, weight = 0.0, 0
    for _, group in frame.groupby("food"):
        rho = group["p"].rank().corr(group["chunk"].rank())
        if np.isfinite(rho):
            total, weight = total + rho * len(group), weight + len(group)
    return float(total / weight) if weight else float("nan")


def _interval(values: np.ndarray) -> tuple[float, float]:
    """The 2.5th and 97.5th percentiles of the finite `values`; NaN when none is."""
    values = np.asarray(values, dtype=np.float64)
    values = values[~np.isnan(values)]
    return (float("nan"), float("nan")) if not len(values) else tuple(float(v) for v in np.percentile(values, [2.5, 97.5]))


def predict_all(checkpoints: dict[str, Path], dataset_dirs: str | Path | list[str] | list[Path],
                label: str = "chunk") -> pd.DataFrame:
    """Every checkpoint's P(spill) on every chunk of one dataset, or of several scored as one set,
    side by side (checks they align), with each chunk's `label` of the kind named ("chunk" or
    "horizon"), whatever each model trained on. With several datasets each chunk's `episode` is
    prefixed with its dataset's directory, so the bootstrap resamples every dataset's episodes as
    distinct units; a dataset listed twice is an InputError."""
    from grits_lab.spillage.chunk_dataset import check_spillage_dataset, refuse_listed_twice
    from grits_lab.spillage.predictor_checkpoint import load_predictor
    from grits_lab.spillage.predictor_training import predict_chunks

    dirs = [Path(dataset_dirs)] if isinstance(dataset_dirs, (str, Path)) else [Path(d) for d in dataset_dirs]
    if len(dirs) > 1:  # before any model runs
        for d in dirs:
            check_spillage_dataset(d)
        refuse_listed_twice(dirs, "--held-out")
    merged: pd.DataFrame | None = None
    for name, path in checkpoints.items():
        predictor = load_predictor(path)
        parts = []
        for d in dirs:
            part, _ = predict_chunks(predictor, d, label=label)
            if len(dirs) > 1:
                part["episode"] = f"{d}/" + part["episode"].astype(str)
            parts.append(part)
        frame = pd.concat(parts, ignore_index=True).rename(columns={"p_spill": f"p_{name}"})
        if merged is None:
            merged = frame
        elif not merged[["episode", "chunk", "label"]].equals(frame[["episode", "chunk", "label"]]):
            raise InputError(f"predictor {name!r} saw different chunks of {', '.join(map(str, dirs))} than the others "
                             "(model.n_action_steps differs?)")
        else:
            merged[f"p_{name}"] = frame[f"p_{name}"].to_numpy()
    assert merged is not None
    return merged


def comparison_markdown(c: Comparison, dataset: str) -> str:
    ref = c.reference
    n_eps = c.predictions["episode"].nunique()
    lines = [
        f"# Spillage predictors on {dataset}",
        "",
        f"{len(c.predictions)} chunks from {n_eps} episodes, labelled by the {c.label} label "
        f"({c.label_meaning or LABEL_MEANING[c.label]}), spill rate {c.predictions['label'].mean():.3f}. "
        f"95 % intervals from {c.n_resamples} paired bootstrap resamples of whole episodes; "
        f"differences are {ref} minus the row's model (p: share of resamples in which {ref} is not better).",
        "",
    ]
    stratum = strata_column(c.predictions)
    position = "AUROC within position" if stratum is None else f"AUROC within {stratum} and position"
    names = {"auroc": "AUROC", "accuracy": "accuracy", "auroc_within": f"AUROC within {stratum}", "auroc_within_position": position,
             "auroc_within_state": "AUROC within state"}
    metrics = [m for m in names if m in c.table.columns]
    spearman = "spearman_position" in c.table.columns
    header = ["model", *(f"{names[m]} [95 %]" for m in metrics[:2]), "ECE", *(f"{names[m]} [95 %]" for m in metrics[2:]),
              *(["Spearman with position"] if spearman else []), *(f"{ref} − {names[m]} [95 %] (p)" for m in metrics)]
    rows = []
    for r in c.table.to_dict("records"):
        baseline = r.get("kind") == "baseline"
        shown = {m: "0.500 (by construction)" if baseline and m == "auroc_within_position" else _with_interval(r, m) for m in metrics}
        cells = [f"{r['model']} (baseline)" if baseline else r["model"], *(shown[m] for m in metrics[:2]),
                 "—" if _missing(r["ece"]) else f"{r['ece']:.3f}", *(shown[m] for m in metrics[2:])]
        if spearman:
            cells.append("—" if _missing(r.get("spearman_position")) else f"{r['spearman_position']:+.2f}")
        for metric in metrics:
            key = f"{ref}_minus_{metric}"
            cells.append("reference" if r["model"] == ref else "—" if _missing(r[key])
                         else f"{r[key]:+.3f} [{r[key + '_lo']:+.3f}, {r[key + '_hi']:+.3f}] ({r[key + '_p']:.3f})")
        rows.append(cells)
    notes = [f"{name} (baseline): {meaning}; a rank, not a probability, so it has no accuracy or ECE. Within "
             f"{'food and ' if stratum else ''}position it ties every pair, so its row's difference there is {ref}'s own "
             "distance from chance, on the same resamples."
             for name, meaning in BASELINES.items() if name in set(c.table["model"])]
    if "auroc_within" in metrics:
        notes.append(f"AUROC within {stratum}: over the (spill, no spill) pairs of chunks of the same {stratum} only, "
                     f"so knowing which {stratum}s spill more earns nothing; guidance needs this one.")
    if "auroc_within_position" in metrics:
        notes.append(f"{position}: over the pairs of chunks {f'of the same {stratum} ' if stratum else ''}at the same index "
                     "in their episodes, so knowing how far into the scoop a chunk is earns nothing; any score of "
                     "the position alone is 0.5 there.")
    if "auroc_within_state" in metrics:
        notes.append("AUROC within state: over the pairs of the policy's samples executed from one and the same state "
                     "(runs that share every step before the branch plan), so the state earns nothing and only "
                     "what the sample does counts: the choice guidance makes.")
    if spearman:
        notes.append(f"Spearman with position: the rank correlation of P(spill) with the chunk's index in its episode"
                     f"{f', within each {stratum}, averaged by its chunks' if stratum else ''} (point estimate). Near -1 the "
                     "model's score is mostly how early in the scoop a chunk is, and guidance following its gradient pushes a "
                     "plan toward what later chunks look like.")
    notes = [line for note in notes for line in ("", note)]
    return "\n".join(lines + [markdown_table(header, rows, right=len(header))] + notes) + "\n"


def _missing(value: Any) -> bool:
    return value is None or (isinstance(value, float) and np.isnan(value))


def _with_interval(row: dict[str, Any], metric: str) -> str:
    """"0.803 [0.624, 0.951]", or "—" where the row has no such metric (a baseline's accuracy)."""
    if _missing(row[metric]):
        return "—"
    return f"{row[metric]:.3f} [{row[metric + '_lo']:.3f}, {row[metric + '_hi']:.3f}]"


def roc_points(scores: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ROC curve's (false positive rate, true positive rate) points, from (0, 0) to (1, 1), one
    point per distinct score: tied chunks (a baseline's equal scores) are one diagonal step, so the
    curve's trapezoid area is the AUROC with ties counted half."""
    scores, y = np.asarray(scores, dtype=np.float64), np.asarray(labels).astype(bool)
    order = np.argsort(-scores, kind="mergesort")
    cuts = np.r_[np.flatnonzero(np.diff(scores[order])), len(scores) - 1] if len(scores) else np.array([], dtype=int)
    tpr = np.concatenate([[0.0], (np.cumsum(y[order]) / max(y.sum(), 1))[cuts]])
    fpr = np.concatenate([[0.0], (np.cumsum(~y[order]) / max((~y).sum(), 1))[cuts]])
    return fpr, tpr


def plot_comparison(c: Comparison, path: Path) -> None:
    """ROC curves and reliability diagrams of every model, side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    y = c.predictions["label"].to_numpy().astype(bool)
    fig, (roc, rel) = plt.subplots(1, 2, figsize=(10, 4.5))
    scores = baseline_scores(c.predictions)
    for r in c.table.to_dict("records"):
        baseline = r.get("kind") == "baseline"
        p = scores[r["model"]] if baseline else c.predictions[f"p_{r['model']}"].to_numpy()
        fpr, tpr = roc_points(p, y)
        roc.plot(fpr, tpr, ls="--" if baseline else "-", label=f"{r['model']}{' (baseline)' if baseline else ''} ({r['auroc']:.3f})")
        if baseline:
            continue
        mean_p, rate, _ = reliability_bins(p, y, c.n_bins)
        rel.plot(mean_p, rate, marker="o", label=f"{r['model']} (ECE {r['ece']:.3f})")
    roc.plot([0, 1], [0, 1], color="grey", lw=0.8, ls="--")
    roc.set(xlabel="false positive rate", ylabel="true positive rate", title="ROC (AUROC)")
    rel.plot([0, 1], [0, 1], color="grey", lw=0.8, ls="--")
    rel.set(xlabel="mean P(spill) in bin", ylabel="spill rate in bin", title="reliability")
    roc.legend(fontsize=8, loc="lower right")
    rel.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)


def write_comparison(c: Comparison, dataset: str, out_dir: str | Path) -> list[Path]:
    """predictor_comparison.{md,csv,json,png} and the per-chunk predictions (Parquet), atomically."""
    out = ensure_writable_dir(Path(out_dir))
    files = [out / "predictor_comparison.md", out / "predictor_comparison.csv", out / "predictor_comparison.json", out / "predictor_comparison.png", out / "predictions.parquet"]
    write_text_atomic(files[0], comparison_markdown(c, dataset))
    write_text_atomic(files[1], c.table.to_csv(index=False))
    models = [{k: v for k, v in row.items() if not (isinstance(v, float) and np.isnan(v))} for row in c.table.to_dict("records")]
    write_json_atomic(files[2], {"dataset": dataset, "label": c.label, "reference": c.reference, "n_resamples": c.n_resamples, "models": models})
    plot_comparison(c, files[3])
    save_parquet_atomic(files[4], c.predictions)
    return files
