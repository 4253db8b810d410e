"""A study's outputs: trials table (CSV, Parquet), best parameters and the Pareto front (YAML), summary, plots.

Everything here is recomputed from the storage, so `grits-lab sweep --report-only` regenerates
the outputs of a study run by other machines. The best-parameter file, and each Pareto-front
trial's file under `front/`, hold the trial's `guidance: {rho, s}` on top of the sweep's
`evaluation.overrides`, which `grits-lab evaluate` takes as an override:
a sweep tuned on the normalized guidance step hands on `step: normalized` with its rho.
"""

from __future__ import annotations

import datetime as _dt
import math
import time
from pathlib import Path

import optuna
import pandas as pd
import yaml
from optuna.trial import FrozenTrial, TrialState

from grits_lab.io import save_parquet_atomic, write_json_atomic, write_text_atomic
from grits_lab.tune.objective import summarize_records
from grits_lab.tune.reference import REFERENCE_FILE, load_references, paired_line, reference_table
from grits_lab.tune.storage import dashboard_command
from grits_lab.tune.study_config import StudyConfig
from grits_lab.tune.study import (
    ENQUEUED_ATTR, ERROR_ATTR, REQUEUED_ATTR, RETRY_OF_ATTR, WORKER_ATTR,
)

METRIC_ATTRS = ("success_rate", "spillage_rate", "scoop_failure_rate", "n_episodes", "n_errors")


def trials_frame(study: optuna.Study, config: StudyConfig) -> pd.DataFrame:
    """One row per trial in the study, in trial-number order."""
    names = config.objective.value_names
    front = {t.number for t in pareto_front(scored_trials(study))}
    rows = []
    for t in study.get_trials(deepcopy=False):
        row = {"number": t.number, "state": t.state.name,
               "rho": t.params.get("rho", math.nan), "s": t.params.get("s", -1)}
        for i, name in enumerate(names):
            row[f"value_{name}"] = t.values[i] if t.values is not None else math.nan
        for key in METRIC_ATTRS:
            row[key] = t.user_attrs.get(key, math.nan)
        row["feasible"] = _feasible(t, config)
        row["pareto_front"] = t.number in front
        row["enqueued"] = bool(t.user_attrs.get(ENQUEUED_ATTR, False))
        row["retry_of"] = t.user_attrs.get(RETRY_OF_ATTR, -1)
        row["requeued"] = bool(t.user_attrs.get(REQUEUED_ATTR, False))
        row["error"] = t.user_attrs.get(ERROR_ATTR, "")
        row["worker"] = t.user_attrs.get(WORKER_ATTR, "")
        row["datetime_start"] = _utc(t.datetime_start)
        row["datetime_complete"] = _utc(t.datetime_complete)
        row["duration_s"] = t.user_attrs.get("duration_s", math.nan)
        rows.append(row)
    frame = pd.DataFrame(rows)
    if not rows:
        return frame
    return frame.astype({"s": "int64", "retry_of": "int64"})


def _utc(moment: _dt.datetime | None) -> _dt.datetime | None:
    """Optuna's trial times (naive, the writing machine's local time) as UTC-aware times, so that trials run on
    machines in several time zones order and read as one clock."""
    return None if moment is None else moment.astimezone(_dt.timezone.utc)


def _feasible(trial: FrozenTrial, config: StudyConfig) -> bool:
    limit = config.objective.max_spillage
    spill = trial.user_attrs.get("spillage_rate")
    return spill is not None and (limit is None or spill <= limit)


def _score(trial: FrozenTrial, config: StudyConfig) -> float:
    """success - spillage_weight * spillage, rounded so that equal scores tie (0.65 - 0.25 and 0.70 - 0.30
    differ in the last bit of a float)."""
    return round(trial.user_attrs["success_rate"] - config.objective.spillage_weight * trial.user_attrs["spillage_rate"], 9)


def pareto_front(trials: list[FrozenTrial]) -> list[FrozenTrial]:
    """Trials not dominated in (maximize success_rate, minimize spillage_rate)."""
    def dominates(a: FrozenTrial, b: FrozenTrial) -> bool:
        sa, pa = a.user_attrs["success_rate"], a.user_attrs["spillage_rate"]
        sb, pb = b.user_attrs["success_rate"], b.user_attrs["spillage_rate"]
        return sa >= sb and pa <= pb and (sa > sb or pa < pb)

    return [t for t in trials if not any(dominates(o, t) for o in trials if o is not t)]


def scored_trials(study: optuna.Study) -> list[FrozenTrial]:
    """Completed trials that carry their rates (the ones a front or a best choice is made from)."""
    return [t for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
            if "success_rate" in t.user_attrs]


def best_trial(study: optuna.Study, config: StudyConfig) -> tuple[FrozenTrial | None, str]:
    """The trial whose (rho, s) the sweep recommends, and a note on how it was chosen.

    Feasible trials (spillage_rate <= max_spillage, when set) first; in multi-objective mode the
    choice is made on the Pareto front; ties in success - spillage_weight * spillage go to the
    trial whose guidance lowered the predictor's median P(spill) of its validation plans the most
    (`p_spill_change`: a handful of episodes often ties on outcomes, and a guidance that does not
    move P(spill) has not acted), then to the earlier trial.
    """
    complete = scored_trials(study)
    if not complete:
        return None, "no completed trial yet"
    pool, note = complete, f"highest success - {config.objective.spillage_weight:g} * spillage"
    if config.objective.max_spillage is not None:
        feasible = [t for t in pool if _feasible(t, config)]
        if feasible:
            pool, note = feasible, note + f" among trials with spillage <= {config.objective.max_spillage:g}"
        else:
            note += f"; NO trial met spillage <= {config.objective.max_spillage:g}"
    if config.objective.mode == "multi":
        pool, note = pareto_front(pool), note + " on the Pareto front"
    def lowered(t: FrozenTrial) -> float:
        change = t.user_attrs.get("p_spill_change")
        return -round(float(change), 6) if change is not None and math.isfinite(change) else -math.inf

    return max(pool, key=lambda t: (_score(t, config), lowered(t), -t.number)), note + \
        "; ties to the larger drop in median P(spill)"


def default_trial(study: optuna.Study, config: StudyConfig) -> FrozenTrial | None:
    """The completed trial of the first enqueued point (the paper's defaults in the shipped sweeps), if any."""
    if not config.enqueue:
        return None
    point = config.enqueue[0]
    for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)):
        if math.isclose(t.params.get("rho", math.nan), point.rho) and t.params.get("s") == point.s:
            return t
    return None


def _metrics(t: FrozenTrial | None) -> dict | None:
    if t is None:
        return None
    return {"trial": t.number, "rho": t.params["rho"], "s": t.params["s"],
            **{k: t.user_attrs.get(k) for k in METRIC_ATTRS}}


def write_outputs(study: optuna.Study, config: StudyConfig, out_dir: Path, storage_description: str,
                  evaluator_label: str, plots: bool = True) -> dict:
    """Write every output under `out_dir`; return the summary that is also saved as summary.json."""
    out_dir = Path(out_dir)
    started = time.time()
    frame = trials_frame(study, config)
    write_text_atomic(out_dir / "trials.csv", frame.to_csv(index=False))
    save_parquet_atomic(out_dir / "trials.parquet", frame)
    best, how = best_trial(study, config)
    defaults = default_trial(study, config)
    references, unstored = load_references(config, out_dir / "records")
    paired = reference_table(references, out_dir / "records", frame)
    if not paired.empty:
        write_text_atomic(out_dir / REFERENCE_FILE, paired.to_csv(index=False))
    else:  # a table left from an earlier reference must not be read as this one's
        (out_dir / REFERENCE_FILE).unlink(missing_ok=True)
    against = _reference_lines(references, paired)
    if best is not None:
        write_text_atomic(out_dir / "best.yaml", _best_yaml(config, best, defaults, how, evaluator_label, against))
    front = sorted(pareto_front(scored_trials(study)), key=lambda t: t.number)
    _write_front(config, front, out_dir / "front", evaluator_label, against)
    summary = {
        "study_name": config.study_name,
        "storage": storage_description,
        "evaluator": evaluator_label,
        "objective": config.objective.mode,
        "n_trials_budget": config.n_trials,
        "states": {s: int((frame["state"] == s).sum()) for s in sorted(frame["state"].unique())} if len(frame) else {},
        "episodes_per_trial": len(config.episodes()),
        "best": _metrics(best),
        "best_rule": how,
        "defaults": _metrics(defaults),
        "pareto_front": [_metrics(t) for t in front],
        "reference": {method: _reference_summary(records, paired[paired["reference"] == method] if len(paired) else paired,
                                                 {t.number for t in front}, best)
                      for method, records in references.items()},
        "dashboard": dashboard_command(storage_description),
        "notes": [f"reference {m}: {why} (the next sweep command runs it before its first trial)"
                  for m, why in unstored.items()],
    }
    if plots:
        summary["notes"].append(plot_tradeoff(study, config, out_dir / "pareto.png", evaluator_label, references))
        summary["notes"].append(plot_importance(study, config, out_dir / "importance.png"))
    summary["notes"] = [n for n in summary["notes"] if n]
    # Only what this call wrote: a plot skipped now, or left from an earlier run, is not named.
    summary["files"] = [name for name in ("trials.csv", "trials.parquet", "best.yaml", "front", REFERENCE_FILE,
                                          "pareto.png", "importance.png")
                        if (out_dir / name).exists() and (out_dir / name).stat().st_mtime >= started - 1.0] + ["summary.json"]
    write_json_atomic(out_dir / "summary.json", summary)
    return summary


def _rates_line(t: FrozenTrial | dict) -> str:
    """The rates of a trial (its attributes) or of a reference (`TrialMetrics.as_attrs`)."""
    a = t.user_attrs if isinstance(t, FrozenTrial) else t
    return (f"success {a['success_rate']:.3f}, spillage {a['spillage_rate']:.3f}, "
            f"scoop failure {a['scoop_failure_rate']:.3f} over {a['n_episodes']} episodes")


def _reference_summary(records: pd.DataFrame, paired: pd.DataFrame, front: set[int], best: FrozenTrial | None) -> dict:
    """A reference's rates, the front's trials and the best trial paired with it (`reference.paired_counts`;
    `best` is None before a trial completes or when its records are unreadable)."""
    def plain(row: dict) -> dict:
        return {k: (v.item() if hasattr(v, "item") else v) for k, v in row.items() if k != "reference"}

    rows = paired.to_dict("records") if len(paired) else []
    chosen = [plain(r) for r in rows if best is not None and r["trial"] == best.number]
    return {**summarize_records(records).as_attrs(),
            "best": chosen[0] if chosen else None,
            "front": [plain(r) for r in rows if r["trial"] in front]}


def _reference_lines(references: dict[str, pd.DataFrame], paired: pd.DataFrame) -> dict[int | None, list[str]]:
    """Comment lines for best.yaml and the front's files: under None each reference's rates, under a
    trial's number that trial against each reference, episode by episode."""
    lines: dict[int | None, list[str]] = {None: [f"# Reference {m} on the same episodes: {_rates_line(summarize_records(r).as_attrs())}."
                                                 for m, r in references.items()]}
    for row in paired.to_dict("records") if len(paired) else []:
        lines.setdefault(int(row["trial"]), []).append(f"# This trial {paired_line(row, str(row['reference']))}.")
    return lines


def guidance_override(config: StudyConfig, trial: FrozenTrial) -> dict:
    """What `trial` ran with, as an evaluation override: the sweep's `evaluation.overrides` (which
    never hold the episode grid: study_config.NOT_OVERRIDABLE) with the trial's `guidance.rho` and `guidance.s`."""
    override = dict(config.evaluation.overrides)
    override["guidance"] = {**override.get("guidance", {}), "rho": float(trial.params["rho"]), "s": int(trial.params["s"])}
    return override


def _override_file(config: StudyConfig, header: list[str], trial: FrozenTrial) -> str:
    """`# header` lines and how to use the file, then `guidance_override`: for `grits-lab evaluate --override`."""
    usage = "# Pass it to `grits-lab evaluate` as an override of the evaluation config."
    body = yaml.safe_dump(guidance_override(config, trial), sort_keys=False)
    return "\n".join([*header, usage]) + "\n" + body


def _write_front(config: StudyConfig, front: list[FrozenTrial], folder: Path, label: str,
                 against: dict[int | None, list[str]]) -> None:
    """One override per Pareto-front trial, `front/trial_NNNNN.yaml`; files of trials no longer on it go."""
    keep = set()
    for t in front:
        name = f"trial_{t.number:05d}.yaml"
        keep.add(name)
        header = [f"# Pareto-front trial {t.number} of sweep `{config.study_name}` (maximize success, minimize spillage).",
                  f"# Evaluator: {label}.", f"# This trial: {_rates_line(t)}.", *against.get(t.number, []),
                  *against.get(None, [])]
        write_text_atomic(folder / name, _override_file(config, header, t))
    if folder.is_dir():
        for stale in folder.glob("trial_*.yaml"):
            if stale.name not in keep:
                stale.unlink()


def _best_yaml(config: StudyConfig, best: FrozenTrial, defaults: FrozenTrial | None, how: str, label: str,
               against: dict[int | None, list[str]]) -> str:
    header = [
        f"# Best guidance of sweep `{config.study_name}`: trial {best.number} ({how}).",
        f"# Evaluator: {label}.",
        f"# This trial: {_rates_line(best)}.",
        *against.get(best.number, []),
    ]
    if defaults is not None:
        header.append(f"# First enqueued point rho={defaults.params['rho']:g} s={defaults.params['s']} "
                      f"(trial {defaults.number}): {_rates_line(defaults)}.")
    header += against.get(None, [])
    return _override_file(config, header, best)


def plot_tradeoff(study: optuna.Study, config: StudyConfig, path: Path, label: str,
                  references: dict[str, pd.DataFrame] | None = None) -> str:
    """Success vs spillage of every completed trial, Pareto front joined, defaults, best and the
    reference methods (`reference.load_references`) marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    complete = scored_trials(study)
    if not complete:
        return "pareto.png not written: no completed trial"
    fig, ax = plt.subplots(figsize=(6, 4.5), dpi=120)
    spill = [t.user_attrs["spillage_rate"] for t in complete]
    success = [t.user_attrs["success_rate"] for t in complete]
    points = ax.scatter(spill, success, c=[t.params["rho"] for t in complete], cmap="viridis",
                        s=[20 + 2 * t.params["s"] for t in complete], alpha=0.8, edgecolors="k", linewidths=0.3)
    fig.colorbar(points, ax=ax, label="rho (marker size: s)")
    front = sorted(pareto_front(complete), key=lambda t: t.user_attrs["spillage_rate"])
    ax.step([t.user_attrs["spillage_rate"] for t in front], [t.user_attrs["success_rate"] for t in front],
            where="post", color="tab:red", marker="x", markersize=8, label=f"Pareto front ({len(front)})")
    defaults = default_trial(study, config)
    if defaults is not None:
        ax.scatter([defaults.user_attrs["spillage_rate"]], [defaults.user_attrs["success_rate"]], marker="*",
                   s=250, facecolors="none", edgecolors="tab:orange", linewidths=1.5,
                   label=f"first enqueued (rho={defaults.params['rho']:g}, s={defaults.params['s']})")
    best, _ = best_trial(study, config)
    if best is not None:
        ax.scatter([best.user_attrs["spillage_rate"]], [best.user_attrs["success_rate"]], marker="o",
                   s=200, facecolors="none", edgecolors="tab:red", linewidths=1.5, label=f"best (trial {best.number})")
    for i, (method, records) in enumerate((references or {}).items()):
        m = summarize_records(records)
        spill.append(m.spillage_rate)  # the axis shows it too
        ax.scatter([m.spillage_rate], [m.success_rate], marker="P", s=160, color=f"C{7 + i}", edgecolors="k",
                   linewidths=0.8, label=f"reference {method} (same episodes)", zorder=5)
    if config.objective.max_spillage is not None:
        ax.axvline(config.objective.max_spillage, color="gray", linestyle="--", label="spillage limit")
    ax.set_xlabel("spillage rate (lower is better)")
    ax.set_ylabel("task success rate (higher is better)")
    ax.set_title(f"{config.study_name}: {len(complete)} trials, {label}", fontsize=9)
    ax.set_xlim(-0.03, max(0.3, max(spill) + 0.05))
    ax.set_ylim(-0.03, 1.03)
    ax.legend(fontsize=7, loc="best", framealpha=0.6)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    _save_figure(fig, path)
    plt.close(fig)
    return ""


def plot_importance(study: optuna.Study, config: StudyConfig, path: Path) -> str:
    """Importance of rho and s per objective (PED-ANOVA); needs at least 2 completed trials."""
    complete = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
    distinct = {(t.params.get("rho"), t.params.get("s")) for t in complete}
    if len(complete) < 2 or len(distinct) < 2:
        return (f"importance.png not written: parameter importance needs at least 2 completed trials "
                f"with different parameters (have {len(complete)} trials, {len(distinct)} distinct)")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import warnings

    from optuna.importance import PedAnovaImportanceEvaluator, get_param_importances

    # PED-ANOVA needs no extra library and is deterministic; it scores how differently rho and s
    # are distributed in the best trials than in all trials, and it reads targets as
    # lower-is-better, hence the signs below.
    names = config.objective.value_names
    signs = [-1.0] if config.objective.mode == "single" else [-1.0, 1.0]
    quantile = min(0.5, max(0.1, 2.0 / len(complete)))
    importances = {}
    for i, name in enumerate(names):
        evaluator = PedAnovaImportanceEvaluator(target_quantile=quantile)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                importances[name] = get_param_importances(
                    study, evaluator=evaluator, params=["rho", "s"],
                    target=lambda t, i=i: signs[i] * t.values[i], normalize=False)
        except (ValueError, RuntimeError, ZeroDivisionError) as exc:
            return f"importance.png not written: {exc}"
    fig, ax = plt.subplots(figsize=(5, 3), dpi=120)
    width = 0.8 / len(names)
    for j, name in enumerate(names):
        values = [importances[name].get(p, 0.0) for p in ("rho", "s")]
        ax.barh([k + j * width for k in range(2)], values, height=width, label=name)
    ax.set_yticks([k + width * (len(names) - 1) / 2 for k in range(2)], ["rho", "s"])
    ax.set_xlabel("PED-ANOVA importance (0: no effect on the best trials)")
    ax.set_title(f"{config.study_name}: parameter importance ({len(complete)} trials)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    _save_figure(fig, path)
    plt.close(fig)
    return ""


def _save_figure(fig, path: Path) -> None:
    import io

    from grits_lab.io import write_bytes_atomic

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    write_bytes_atomic(path, buffer.getvalue())
