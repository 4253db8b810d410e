"""Guides scored where guidance acts: the policy's other samples from one and the same state.

Runs of `python -m studies.outcome_sensitivity branch` on the same seeds that differ only in the draw (with one
plan k, hooks.py; docs/evaluation.md, "Branches from one state") share every step of an
episode up to plan k and then execute another sample of the policy there. The chunk each run
executes at plan k is one of the policy's alternatives from that state, and its label says what
that choice led to. Guidance picks among (and moves) such samples, so what a guide must do is rank
them within a state; the pooled AUROC also credits knowing which states spill.

A run with a nudge (--offset) as well replays its draw's sample nudged from the branch plan
on, by a distance no observation resolves: draw 0 and such replays of it are K outcomes of one
sample from one state, whose spread is the chance part no guide can rank (docs/evaluation.md,
"Branches from one state").

Per state (food, level, seed) the K draws give K outcomes of one state. `outcome_spread` says how
often they disagree and how much of the label's variance lies within states; `selection` says how
often a draw spills when each guide picks the draw it scores lowest, against the policy's own
(draw 0) and the best any choice among the K could do.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from grits_lab.errors import InputError


@dataclass(frozen=True)
class BranchRun:
    """One run directory of a branch study: its rollout-chunk dataset, branch plan, draw and nudge."""

    path: Path
    dataset: Path
    plan: int
    draw: int
    delivers: bool  # the run played the transfer and pour (its horizon label runs to delivery, else to the scoop's end)
    offset_m: float = 0.0  # the nudge from the branch plan on, metres (0: not nudged)
    offset_draw: int = 0  # the nudge's draw (0 when not nudged)

    @property
    def key(self) -> tuple[int, float, int]:
        return (self.draw, self.offset_m, self.offset_draw)

    @property
    def own(self) -> bool:
        """The policy's own episode: draw 0, not nudged."""
        return self.key == (0, 0.0, 0)


def branch_runs(runs: list[str | Path], method: str = "dp") -> list[BranchRun]:
    """The runs of one branch study, in the order given. InputError, before any model runs, for
    fewer than two runs, a run without a branch plan (`_hook_settings`) or without
    rollout chunks of `method`, runs that branch at different plans or whose horizons end at
    different stages (`transfer.enabled`), a draw listed twice, or no draw 0."""
    if len(runs) < 2:
        raise InputError(f"`branches` needs at least two runs of one branch plan (got {len(runs)})")
    from grits_lab.evaluation.evaluation_run import ROLLOUT_CHUNKS_DIR

    out = []
    for run in map(Path, runs):
        config = run / "config.yaml"
        if not config.is_file():
            raise InputError(f"{run}: no config.yaml; give run directories of `grits-lab evaluate`")
        data = yaml.safe_load(config.read_text()) or {}
        plan, draw, offset, offset_draw = _hook_settings(run, data)
        if plan < 0:
            raise InputError(f"{run}: its episodes branch at no plan; a branch study's runs branch at one plan "
                             "(`python -m studies.outcome_sensitivity branch ... --plan K`)")
        dataset = run / ROLLOUT_CHUNKS_DIR / method
        if not dataset.is_dir():
            raise InputError(f"{run}: no rollout chunks of method {method!r} at {dataset} (evaluate with rollout_chunks: true)")
        delivers = bool((data.get("transfer") or {}).get("enabled", True))
        out.append(BranchRun(run, dataset, plan, draw, delivers, offset, offset_draw if offset else 0))
    if len({r.plan for r in out}) > 1:
        raise InputError("the runs branch at different plans: " + ", ".join(f"{r.path} at {r.plan}" for r in out))
    if len({r.delivers for r in out}) > 1:
        raise InputError("some runs play the transfer and pour and some do not (transfer.enabled): their horizon labels end "
                         "at different points: " + ", ".join(f"{r.path}: {r.delivers}" for r in out))
    keys = [r.key for r in out]
    if len(set(keys)) < len(keys):
        raise InputError("a branch draw is listed twice (draw, nudge, nudge draw): "
                         + ", ".join(f"{r.path}: {r.key}" for r in out))
    if not any(r.own for r in out):
        raise InputError(f"no run is draw 0 without a nudge, the policy's own episode, which the picks are compared with "
                         f"(draw, nudge, nudge draw: {keys})")
    return out


def _hook_settings(run: Path, data: dict) -> tuple[int, int, float, int]:
    """(branch plan, -1: none; branch draw; nudge in metres; nudge draw) of a run: from its config.yaml's
    `scoop` block where runs made before the hook wrote them there, else from its records' hook
    columns (`OutcomeHook.record_columns`; a run holds one setting)."""
    scoop = data.get("scoop") or {}
    if scoop.get("branch_plan") is not None:
        return (int(scoop["branch_plan"]), int(scoop.get("branch_draw", 0)), float(scoop.get("action_offset", 0.0) or 0.0),
                int(scoop.get("action_offset_draw", 0)))
    records = run / "episodes.parquet"
    if not records.is_file():
        return (-1, 0, 0.0, 0)
    frame = pd.read_parquet(records)
    columns = ("scoop_branch_plan", "scoop_branch_draw", "scoop_action_offset_m", "scoop_action_offset_draw")
    if frame.empty or any(c not in frame.columns for c in columns):
        return (-1, 0, 0.0, 0)
    first = frame.iloc[0]
    return (int(first[columns[0]]), int(first[columns[1]]), float(first[columns[2]]), int(first[columns[3]]))


def branch_predictions(checkpoints: dict[str, Path], runs: list[str | Path], method: str = "dp", label: str = "horizon") -> pd.DataFrame:
    """Every checkpoint's P(spill) on the chunk each run executed at the branch plan: one row per
    (state, run) with `state` (the episode, the bootstrap unit), `branch` (the run's index in `runs`),
    `draw`, `offset_m`, `offset_draw`, `own` (draw 0, not nudged), `food`, `label` and `p_<model>`.

    Only states every run holds are kept (those some runs lack are named in
    `frame.attrs["states_left_out"]`, which `outcome_spread` counts), and only states whose runs saw the same composite cloud
    at the branch plan: a state whose clouds differ was not shared (the runs diverged before the
    plan: other code, other CPU kernels) and is an InputError naming it. With no checkpoints the
    frame holds the labels alone (what `outcome_spread` and the own and best rows of `selection` need).
    """
    from grits_lab.data.format import read_episode
    from grits_lab.spillage.compare import predict_all

    branches = branch_runs(runs, method)
    plan = branches[0].plan
    if checkpoints:
        frame = predict_all(checkpoints, [b.dataset for b in branches], label=label)
    else:
        frame = _labels_at(branches, plan, label)
    parts = []
    for i, b in enumerate(branches):
        prefix = f"{b.dataset}/"
        part = frame[frame["episode"].str.startswith(prefix) & (frame["chunk"] == plan)].copy()
        part["state"] = part["episode"].str.slice(len(prefix))
        part["branch"], part["draw"], part["offset_m"], part["offset_draw"], part["own"] = i, b.draw, b.offset_m, b.offset_draw, b.own
        parts.append(part)
    shared = set.intersection(*(set(p["state"]) for p in parts))
    every = set.union(*(set(p["state"]) for p in parts))
    if not shared:
        raise InputError(f"no episode reached plan {plan} in every run of {', '.join(str(b.path) for b in branches)}")
    clouds: dict[str, np.ndarray] = {}
    for b in branches:
        for file in sorted(shared):
            arrays, _ = read_episode(b.dataset / file)
            cloud = np.asarray(arrays["chunk_cloud"][plan])
            if file in clouds and not np.array_equal(clouds[file], cloud):
                raise InputError(f"{b.path}: episode {file} saw another cloud at plan {plan} than {branches[0].path}: "
                                 "the runs did not share the state (other code or CPU kernels?)")
            clouds.setdefault(file, cloud)
    out = pd.concat(parts, ignore_index=True)
    out = out[out["state"].isin(shared)].copy()
    out["episode"] = out["state"]
    out = out.sort_values(["state", "branch"], kind="stable").reset_index(drop=True)
    out.attrs["states_left_out"] = sorted(every - shared)  # reached the plan in some runs only (a failed episode, an unfinished run)
    return out


def _labels_at(branches: list[BranchRun], plan: int, label: str) -> pd.DataFrame:
    """`episode` (dataset-prefixed, as predict_all names several datasets' episodes), `chunk`,
    `food` and `label` of every run's chunk at `plan`, read from the rollout chunks without a model."""
    from grits_lab.data.chunk_labels import LABEL_ARRAYS
    from grits_lab.data.format import read_episode
    from grits_lab.spillage.chunk_dataset import check_spillage_dataset

    rows = []
    for b in branches:
        index = check_spillage_dataset(b.dataset, label=label, label_key="--label")
        foods = dict(zip(index["file"].astype(str), index["food"].astype(str))) if "food" in index.columns else {}
        for file in sorted(index["file"].astype(str)):
            labels = read_episode(b.dataset / file, keys=[LABEL_ARRAYS[label]])[0][LABEL_ARRAYS[label]]
            if len(labels) > plan:
                rows.append({"episode": f"{b.dataset}/{file}", "chunk": plan, "food": foods.get(file, ""), "label": np.int8(labels[plan])})
    return pd.DataFrame(rows, columns=["episode", "chunk", "food", "label"])


def outcome_spread(frame: pd.DataFrame) -> dict[str, Any]:
    """How the draws of one state disagree, for the `label` column of `branch_predictions`.

    states, left_out (states some runs lack, from `branch_predictions`), draws (per state, the fewest), rate m (over every draw), mixed (states whose draws do not
    all agree), all_spill, within = mean over states of the unbiased s (K - s) / (K (K - 1)) (s of K
    draws spilled), an estimate of E[p (1 - p)] with p a state's chance of a spill, `within_share`:
    the share of the label's variance m (1 - m) that lies within states (law of total variance,
    mean of s (K - s) / K^2 over it: what a guide that sees the trajectory could rank and the state
    alone cannot), and `ceiling_state_only`: the best AUROC any score of the state alone can reach
    (studies/outcome_sensitivity/ceiling.py, with v = within).
    """
    from studies.outcome_sensitivity.ceiling import max_auroc

    grouped = frame.groupby("state")["label"]
    s, k = grouped.sum().to_numpy(dtype=np.float64), grouped.size().to_numpy(dtype=np.float64)
    rate = float(frame["label"].mean())
    within = float(np.mean(s * (k - s) / (k * (k - 1)))) if (k > 1).all() else float("nan")
    total = float(np.mean(frame["label"].to_numpy(dtype=np.float64) ** 2)) - rate**2  # m (1 - m) for a 0/1 label
    share = float(np.sum(s * (k - s) / k) / len(frame)) / total if total > 0 else float("nan")
    return {"states": int(len(s)), "left_out": len(frame.attrs.get("states_left_out", [])), "draws": int(k.min()), "rate": rate,
            "mixed": int(((s > 0) & (s < k)).sum()),
            "all_spill": int((s == k).sum()), "within": within, "within_share": share,
            "ceiling_state_only": max_auroc(rate, within) if 0 < rate < 1 else float("nan")}


SELECTION_ROWS = ("own", "best", "random", "best_samples", "best_replays")  # `selection`'s rows that no model picks


def check_model_names(models: list[str]) -> None:
    """InputError when a model is named as one of `selection`'s own rows (SELECTION_ROWS)."""
    taken = sorted(set(models) & set(SELECTION_ROWS))
    if taken:
        raise InputError(f"a predictor is named {taken[0]!r}, a row of the selection table; rename it (config `name`)")


def samples_and_replays(frame: pd.DataFrame) -> tuple[list[int], list[int]]:
    """The `branch` indices of the policy's samples (runs without a nudge: draw 0 and other draws) and
    of the replays of its own sample (draw 0, nudged or not), each with the own run (draw 0, not
    nudged) first and then the others in the order given, cut to k, the smaller count: the best of
    either is a best of k, and both hold the own run. ([], []) unless the runs hold at least one
    other draw and one nudged replay (or the frame names no `draw`, `offset_m` and `own`)."""
    if not {"draw", "offset_m", "own"} <= set(frame.columns):
        return [], []
    runs = frame.drop_duplicates("branch").sort_values(["own", "branch"], ascending=[False, True], kind="stable")
    samples = runs.loc[runs["offset_m"] == 0, "branch"].tolist()
    replays = runs.loc[runs["draw"] == 0, "branch"].tolist()
    if len(samples) < 2 or len(replays) < 2:
        return [], []
    k = min(len(samples), len(replays))
    return samples[:k], replays[:k]


def selection(frame: pd.DataFrame, models: list[str], n_resamples: int = 1000, seed: int = 0) -> pd.DataFrame:
    """Spill rate when each model picks, in every state, the draw it scores lowest (ties: the first
    run given), beside the policy's own draw 0 (`own`, the rows whose `own` is true) and the best
    choice among the draws (`best`: a state spills only when every draw does) and a draw picked at
    random (`random`: the state's mean label, the expected rate). Rows: "own", "best", "random", then
    one per model, with the rate, its 95 % interval and the paired difference to `own` (picked minus
    own) from resampling states; a model's row also holds `minus_random` (picked minus random, with
    its interval), which does not lean on draw 0 being a typical draw.

    When the runs hold both other draws and nudged replays of draw 0 (`samples_and_replays`), two
    rows come after "best": "best_samples", the best of k of the policy's samples, and
    "best_replays", the best of k replays of its own sample, the chance floor at k runs; the
    first also holds `minus_replays` (and its interval): what choosing among samples removes beyond
    what k tries of one sample do by chance.
    """
    check_model_names(models)
    states = sorted(frame["state"].unique())
    idx = {s: i for i, s in enumerate(states)}
    frame = frame.sort_values(["state", "branch"], kind="stable")
    rows = frame["state"].map(idx).to_numpy()
    y = frame["label"].to_numpy(dtype=np.float64)
    own = np.full(len(states), np.nan)
    first = frame["own"].to_numpy(dtype=bool)
    own[rows[first]] = y[first]
    per_state: dict[str, np.ndarray] = {"own": own, "best": np.array([y[rows == i].min() for i in range(len(states))]),
                                        "random": np.array([y[rows == i].mean() for i in range(len(states))])}
    samples, replays = samples_and_replays(frame)
    if samples:
        branch = frame["branch"].to_numpy()
        for name, among in (("best_samples", samples), ("best_replays", replays)):
            keep = np.isin(branch, among)
            per_state[name] = np.array([y[(rows == i) & keep].min() for i in range(len(states))])
    for m in models:
        p = frame[f"p_{m}"].to_numpy(dtype=np.float64)
        picked = np.empty(len(states))
        for i in range(len(states)):
            at = np.flatnonzero(rows == i)
            picked[i] = y[at[np.argmin(p[at])]]
        per_state[m] = picked
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, len(states), (n_resamples, len(states)))

    def mean_and_interval(key: str, per_state_values: np.ndarray) -> dict[str, float]:
        """`key`, `key_lo`, `key_hi`: the mean over states and its 95 % interval over the resampled states."""
        boot = per_state_values[draws].mean(axis=1)
        return {key: float(per_state_values.mean()), f"{key}_lo": float(np.percentile(boot, 2.5)),
                f"{key}_hi": float(np.percentile(boot, 97.5))}

    out = []
    for name, values in per_state.items():
        row = {"choice": name, **mean_and_interval("rate", values)}
        if name != "own":
            row.update(mean_and_interval("minus_own", values - per_state["own"]))
        if name in models:
            row.update(mean_and_interval("minus_random", values - per_state["random"]))
        if name == "best_samples":
            row.update(k=len(samples), **mean_and_interval("minus_replays", values - per_state["best_replays"]))
        out.append(row)
    return pd.DataFrame(out)


SCOOP_ONLY_HORIZON = "food spilled from the chunk's first action to the end of the scoop, where these runs stop: transfer.enabled is false"


def branch_markdown(spread: dict[str, Any], picked: pd.DataFrame, plan: int, label: str) -> str:
    """The outcome spread and the selection table as a markdown section."""
    from grits_lab.markdown import markdown_table

    lines = [
        f"## The draws of one state (plan {plan}, {label} label)",
        "",
        f"{spread['states']} states, at least {spread['draws']} draws each, spill rate {spread['rate']:.3f}. States whose draws "
        f"disagree: {spread['mixed']} of {spread['states']}; whose draws all spill: {spread['all_spill']}. "
        f"{spread['within_share']:.0%} of the label's variance lies within states (E[p(1-p)] {spread['within']:.3f}, "
        f"p a state's chance of a spill); the best AUROC of any score of the state alone is {spread['ceiling_state_only']:.3f}.",
        "",
    ]
    if spread.get("left_out"):
        lines[-2] += (f" Left out: {spread['left_out']} states that reached the plan in some runs only (an episode that failed "
                      "before it, or a run not finished).")
    names = {"own": "the policy's own sample (draw 0)", "best": "the best of the draws (a state spills only if every draw does)",
             "random": "a draw picked at random (the state's mean)"}
    k = picked.set_index("choice")["k"].get("best_samples") if "k" in picked.columns else None
    if k is not None:
        names["best"] = "the best of every run given (samples and replays)"
        names["best_samples"] = f"the best of {k:.0f} of the policy's samples (draw 0 and other draws)"
        names["best_replays"] = f"the best of {k:.0f} runs of its own sample (draw 0 and nudged replays): chance alone"
    def interval(r: dict[str, Any], key: str, sign: str = "+") -> str:
        """`key` of row `r` with its interval, "" where the row has none."""
        if pd.isna(r.get(key, float("nan"))):
            return ""
        return f"{r[key]:{sign}.3f} [{r[f'{key}_lo']:{sign}.3f}, {r[f'{key}_hi']:{sign}.3f}]"

    rows = []
    for r in picked.to_dict("records"):
        diff = "reference" if r["choice"] == "own" else interval(r, "minus_own")
        rows.append([names.get(r["choice"], f"picked by {r['choice']} (lowest P(spill))"), interval(r, "rate", sign=""), diff,
                     interval(r, "minus_random")])
    lines.append(markdown_table(["choice in each state", "spill rate [95 %]", "minus the own sample [95 %]", "minus a random pick [95 %]"],
                                rows, right=2))
    if k is not None:
        r = picked.set_index("choice").loc["best_samples"].to_dict()
        lines += ["", f"Best of {k:.0f} samples minus best of {k:.0f} replays, paired by state: {interval(r, 'minus_replays')}: "
                  "what choosing among the policy's samples "
                  "removes beyond what as many tries of one sample remove by chance."]
    lines += ["", "Intervals from resampling states. A guide that ranks the draws of a state no better than chance picks "
              "a draw that spills as often as one picked at random; the own sample is one draw, which may spill more or "
              "less than the state's mean."]
    return "\n".join(lines) + "\n"
