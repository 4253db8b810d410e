"""The scoop convergence study: the same scoops at several physics settings, plain and nudged, and the choice rule.

A study config (configs/scoop_convergence.yaml) names an evaluation config (the episodes), the
physics settings (`sim.time_step`, `sim.solver_iterations`; the last listed is the finest, the
reference), the nudge (studies/outcome_sensitivity/hooks.py `OutcomeHook`: every scoop action moved
`offset` metres, in each of `draws`) and the decision's tolerance. `run` plays one evaluation run
directory per setting and variant, OUTPUT/<setting>/plain and OUTPUT/<setting>/nudge<draw>, each with
the framework's `evaluate` (resumable, records in episodes.parquet). `summarize` reads them back:

- per setting and method, from the plain runs: the rate of episodes that spilled during the scoop, of
  those that lost a particle over the source bowl's rim and of those that lost one off the moving
  spoon (record columns `spillage`, `spilled_scoop_over_rim`, `spilled_scoop_off_spoon`), with Wilson
  95 % intervals; the particles spilled and scooped (sums and per-episode means); the mean wall time
  of an episode (the setting's cost on the machine that ran it);
- the nudge's change rate: of the plain episodes paired with a nudged draw on the same seed, the
  share whose `spillage` differs, all draws pooled, with its Wilson interval;
- the choice: the coarsest setting each of whose four rates lies within the finest setting's
  interval of the same rate (the finest is always within its own). It is *decided* when every one of
  the finest setting's intervals has a half width of at most `decision.max_half_width`; otherwise the
  summary says how many episodes per interval would narrow it to that at the measured rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import pandas as pd

from grits_lab.config import config_from_dict, load_yaml, merge_mappings, require
from grits_lab.errors import ConfigError, InputError
from grits_lab.intervals import Z_95, Rate, format_rate, rate

PLAIN = "plain"
SUMMARY_FILE = "convergence.csv"
DECISION_FILE = "decision.md"
# The rates the choice compares, in the summary's order: record column (or "nudge_change") -> its name.
RATES = {
    "spillage": "spill during the scoop",
    "over_rim": "lost over the rim",
    "off_spoon": "lost off the spoon",
    "nudge_change": "changed by the nudge",
}


@dataclass
class PhysicsSetting:
    """One setting of the scoop's physics: `sim.time_step` (seconds) and `sim.solver_iterations`."""

    time_step: float
    solver_iterations: int

    def __post_init__(self) -> None:
        require(self.time_step > 0, "time_step", self.time_step, "positive seconds")
        require(self.solver_iterations >= 1, "solver_iterations", self.solver_iterations, "at least 1")


@dataclass
class NudgeSettings:
    offset: float = 0.0005  # metres
    draws: list[int] = field(default_factory=lambda: [0, 1])


@dataclass
class DecisionSettings:
    max_half_width: float = 0.1  # fraction: the Wilson 95 % half width every finest rate must reach


@dataclass
class ConvergenceConfig:
    """The study config (configs/scoop_convergence.yaml); `settings` in order, coarsest first, finest last."""

    evaluation: str
    settings: dict[str, PhysicsSetting]
    overrides: dict[str, Any] = field(default_factory=dict)
    nudge: NudgeSettings = field(default_factory=NudgeSettings)
    decision: DecisionSettings = field(default_factory=DecisionSettings)

    def __post_init__(self) -> None:
        require(len(self.settings) >= 2, "settings", list(self.settings), "at least two settings (the last is the reference)")
        for name in self.settings:
            require(name not in ("", PLAIN) and "/" not in name, "settings", name, "a folder name")
        listed = list(self.settings.items())
        for (name, a), (_, b) in zip(listed, listed[1:]):  # coarsest first: the choice rule reads the order
            finer = b.time_step <= a.time_step and b.solver_iterations >= a.solver_iterations and \
                (b.time_step, b.solver_iterations) != (a.time_step, a.solver_iterations)
            require(finer, "settings", list(self.settings),
                    f"coarsest first: each setting a smaller or equal time_step and as many or more solver_iterations "
                    f"than the one before it ({name} is not coarser than the next)")
        require(len(self.nudge.draws) >= 1 and len(set(self.nudge.draws)) == len(self.nudge.draws), "nudge.draws",
                self.nudge.draws, "a non-empty list without repeats")
        require(0.0 < self.nudge.offset <= 0.01, "nudge.offset", self.nudge.offset, "in (0, 0.01] metres")
        require(0.0 < self.decision.max_half_width < 0.5, "decision.max_half_width", self.decision.max_half_width, "in (0, 0.5)")


def load_convergence_config(path: str | Path) -> ConvergenceConfig:
    """The study config at `path`; ConfigError naming the file and key when a value is wrong."""
    try:
        return config_from_dict(ConvergenceConfig, load_yaml(path))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def variant_names(config: ConvergenceConfig) -> list[str]:
    return [PLAIN, *(f"nudge{d}" for d in config.nudge.draws)]


def evaluation_configs(config: ConvergenceConfig, output_dir: str | Path, overrides: dict[str, Any] | None = None) -> list[tuple[str, str, Any, Any]]:
    """(setting, variant, EvaluationConfig, hook or None) of every run, the plain runs of every
    setting first, then each nudge draw's; all loaded (and so checked) before any episode runs.
    `overrides` are merged over the study config's own `overrides` (e.g. `checkpoints`, `methods`)."""
    from grits_lab.evaluation.evaluation_config import load_evaluation_config
    from studies.outcome_sensitivity.hooks import OutcomeHook

    merged = merge_mappings(config.overrides, overrides or {})
    runs = []
    for variant in variant_names(config):
        hook = None if variant == PLAIN else OutcomeHook(offset=config.nudge.offset, offset_draw=int(variant[len("nudge"):]))
        for name, setting in config.settings.items():
            layer = merge_mappings(merged, {
                "output_dir": str(Path(output_dir) / name / variant),
                "sim": {"time_step": setting.time_step, "solver_iterations": setting.solver_iterations}})
            evaluation = load_evaluation_config(config.evaluation, layer)
            evaluation = replace(evaluation, run_id=f"{evaluation.run_id}_{name}_{variant}")
            if evaluation.transfer.enabled:
                raise ConfigError(f"{config.evaluation}: `transfer.enabled` must be false: the study plays the scoop alone")
            runs.append((name, variant, evaluation, hook))
    return runs


def run_study(config: ConvergenceConfig, output_dir: str | Path, overrides: dict[str, Any] | None = None,
              progress: bool = True, only: list[str] | None = None) -> int:
    """Play (or resume) every run of the study under `output_dir`; `only`: these settings. Exit status 1
    when an episode failed (its error is in its records), else 0."""
    import yaml

    from grits_lab.config import config_to_dict
    from grits_lab.evaluation.evaluation_run import evaluate, failed_episodes_line
    from grits_lab.evaluation.methods import method_checkpoints
    from grits_lab.io import ensure_writable_dir, write_text_atomic

    runs = evaluation_configs(config, output_dir, overrides)
    if only:
        unknown = [n for n in only if n not in config.settings]
        if unknown:
            raise InputError(f"--settings {' '.join(unknown)}: not a setting of the config (it has {', '.join(config.settings)})")
        runs = [r for r in runs if r[0] in only]
    for _, _, evaluation, _ in runs[:1]:  # every run has the same methods and checkpoints: a missing one before any work
        for method in evaluation.methods:
            method_checkpoints(method, evaluation.checkpoints)

    out = ensure_writable_dir(output_dir)
    recorded = out / STUDY_FILE
    text = yaml.safe_dump(config_to_dict(config), sort_keys=False)
    if recorded.is_file() and config_from_dict(ConvergenceConfig, load_yaml(recorded)) != config:
        raise InputError(f"{out} holds a study of another config ({recorded}); give another --output-dir")
    write_text_atomic(recorded, text)
    status = 0
    for name, variant, evaluation, hook in runs:
        records = evaluate(evaluation, progress=progress, hook=hook)
        print(f"{name}/{variant}: {len(records)} episodes in {evaluation.output_dir}")
        failed = failed_episodes_line(records, f"{evaluation.output_dir}/episodes.parquet")
        if failed:
            print(f"error: {failed}")
            status = 1
    return status


# ---------------------------------------------------------------------------------------------------- summary

def _episodes(run_dir: Path) -> pd.DataFrame:
    from grits_lab.report.run_compare import with_paired_outcomes
    from grits_lab.report.run_records import load_run

    frame = load_run(run_dir).episodes
    if frame is None or frame.empty:
        raise InputError(f"{run_dir}: no episode records")
    return with_paired_outcomes(frame)


def study_runs(output_dir: str | Path) -> dict[str, dict[str, Path]]:
    """{setting: {variant: run directory}} of the run directories under `output_dir` that hold records,
    settings in the order of the study config `run` wrote (OUTPUT/study.yaml); InputError when there
    is none or the study config is missing."""
    out = Path(output_dir)
    if not (out / STUDY_FILE).is_file():
        raise InputError(f"{out}: not a scoop convergence study (no {STUDY_FILE}; write one with `run`)")
    config = config_from_dict(ConvergenceConfig, load_yaml(out / STUDY_FILE))
    found = {name: {v: out / name / v for v in variant_names(config) if (out / name / v / "episodes.parquet").is_file()}
             for name in config.settings}
    found = {name: runs for name, runs in found.items() if PLAIN in runs}
    if not found:
        raise InputError(f"{out}: no setting has plain episodes yet (expected {out}/<setting>/plain/episodes.parquet)")
    return found


STUDY_FILE = "study.yaml"  # the study config `run` played, beside its run directories


def setting_rows(plain: pd.DataFrame, nudged: list[pd.DataFrame]) -> list[dict[str, Any]]:
    """One row per method of `plain` (records of one setting's plain run, with paired outcomes): counts,
    rates with Wilson intervals (`<rate>_k`, `_n`, `_rate`, `_low`, `_high`) and costs. `nudged`: the
    records of the same setting's nudged runs, paired with `plain` on (method, food, level, trial)."""
    from grits_lab.report.run_compare import compare_runs

    rows = []
    for method in dict.fromkeys(plain["method"]):
        mine = plain[(plain["method"] == method) & ~plain["is_error"]]
        row: dict[str, Any] = {"method": method, "episodes": int(len(mine)),
                               "errors": int(((plain["method"] == method) & plain["is_error"]).sum())}
        rates = {"spillage": rate(int(mine["spillage"].astype(bool).sum()), len(mine)),
                 "over_rim": rate(int((mine["spilled_scoop_over_rim"] > 0).sum()), len(mine)),
                 "off_spoon": rate(int((mine["spilled_scoop_off_spoon"] > 0).sum()), len(mine))}
        changed = paired = 0
        for other in nudged:
            if not (other["method"] == method).any():
                continue
            table = compare_runs(plain[plain["method"] == method], other[other["method"] == method])
            paired += int(table["paired"].sum())
            changed += int((table["spillage_only_before"] + table["spillage_only_after"]).sum())
        rates["nudge_change"] = rate(changed, paired)
        for key, r in rates.items():
            row.update({f"{key}_k": r.k, f"{key}_n": r.n, f"{key}_rate": r.rate, f"{key}_low": r.low, f"{key}_high": r.high})
        for column in ("spilled", "scooped", "spilled_scoop_over_rim", "spilled_scoop_off_spoon"):
            values = pd.to_numeric(mine[column], errors="coerce")
            row[f"{column}_sum"] = int(values.sum())
            row[f"{column}_mean"] = float(values.mean()) if len(values) else math.nan
        row["wall_time_s_mean"] = float(pd.to_numeric(mine["wall_time_s"], errors="coerce").mean()) if len(mine) else math.nan
        rows.append(row)
    return rows


ALL_LEVELS = "all"  # the `level` of a row that pools every level; the choice reads these rows


def convergence_table(output_dir: str | Path) -> tuple[pd.DataFrame, ConvergenceConfig]:
    """The summary's table: one row per (setting, level, method), settings in the config's order, the
    levels pooled (`ALL_LEVELS`) first and then each level when the records hold several."""
    runs = study_runs(output_dir)
    config = config_from_dict(ConvergenceConfig, load_yaml(Path(output_dir) / STUDY_FILE))
    rows = []
    for name, variants in runs.items():
        setting = config.settings[name]
        plain = _episodes(variants[PLAIN])
        nudged = [_episodes(path) for v, path in variants.items() if v != PLAIN]
        levels = [ALL_LEVELS, *dict.fromkeys(plain["level"])]
        for level in levels:
            mine = (lambda f: f) if level == ALL_LEVELS else (lambda f, lv=level: f[f["level"] == lv])
            for row in setting_rows(mine(plain), [mine(f) for f in nudged]):
                rows.append({"setting": name, "time_step": setting.time_step, "solver_iterations": setting.solver_iterations,
                             "nudge_draws": len(nudged), "level": level, **row})
    return pd.DataFrame(rows), config


def _rate_of(row: pd.Series, key: str) -> Rate:
    return Rate(int(row[f"{key}_k"]), int(row[f"{key}_n"]), float(row[f"{key}_rate"]), float(row[f"{key}_low"]),
                float(row[f"{key}_high"]))


def episodes_for_half_width(p: float, half_width: float, z: float = Z_95) -> int:
    """Episodes n at which a rate near `p` has a 95 % interval of about +-`half_width` (normal
    approximation z^2 p (1 - p) / h^2, with p taken no closer to 0 or 1 than 0.05)."""
    p = min(max(p, 0.05), 0.95)
    return int(math.ceil(z * z * p * (1.0 - p) / (half_width * half_width)))


@dataclass
class Choice:
    """The choice rule's verdict for one method (`choose`)."""

    method: str
    reference: str  # the finest setting
    chosen: str | None  # the coarsest setting within the reference's intervals; None: the reference has no episodes
    within: dict[str, list[str]]  # setting -> the rates of it outside the reference's interval (empty: within)
    decided: bool
    needed: int  # episodes per rate the widest reference interval needs to reach the tolerance (0 when decided)
    widest: str  # the rate with the widest reference interval

    def sentence(self, max_half_width: float) -> str:
        if self.chosen is None:
            return f"{self.method}: the finest setting {self.reference} has no episodes; nothing is chosen."
        outside = "; ".join(f"{s}: {', '.join(RATES[r] for r in bad)} outside" for s, bad in self.within.items() if bad)
        verdict = (f"decided: every interval of {self.reference} is within +-{max_half_width:g}" if self.decided else
                   f"not decided at this n: the interval of {self.reference}'s {RATES[self.widest]} is wider than "
                   f"+-{max_half_width:g}; about {self.needed} episodes per rate would narrow it to that")
        return (f"{self.method}: the coarsest setting within {self.reference}'s intervals is **{self.chosen}**"
                f"{' (' + outside + ')' if outside else ''}; {verdict}.")


def choose(table: pd.DataFrame, settings: list[str], method: str, max_half_width: float) -> Choice:
    """The coarsest of `settings` (coarsest first, the last the reference) whose four rates (`RATES`) for
    `method` each lie within the reference's Wilson interval; a rate with no episodes on either side
    (no nudged run yet) is not compared. Decided when every reference interval with episodes has a half
    width of at most `max_half_width` and every rate has been measured at the reference."""
    rows = {r["setting"]: r for _, r in table[(table["method"] == method) & (table["level"] == ALL_LEVELS)].iterrows()}
    reference = settings[-1]
    if reference not in rows:
        return Choice(method, reference, None, {}, False, 0, "spillage")
    ref = {key: _rate_of(rows[reference], key) for key in RATES}
    within: dict[str, list[str]] = {}
    for name in settings:
        if name not in rows:
            continue
        mine = {key: _rate_of(rows[name], key) for key in RATES}
        within[name] = [key for key in RATES if not (ref[key].missing or mine[key].missing)
                        and not ref[key].low <= mine[key].rate <= ref[key].high]
    chosen = next(name for name in settings if name in within and not within[name])
    halves = {key: (r.high - r.low) / 2.0 if not r.missing else math.inf for key, r in ref.items()}
    widest = max(halves, key=halves.get)
    decided = halves[widest] <= max_half_width and all(name in rows for name in settings)
    p = ref[widest].rate if not ref[widest].missing else 0.5
    return Choice(method, reference, chosen, within, decided, 0 if decided else episodes_for_half_width(p, max_half_width), widest)


def summary_markdown(table: pd.DataFrame, config: ConvergenceConfig, output_dir: str | Path) -> str:
    """The summary page: the table per method and the choice rule's verdict."""
    from grits_lab.markdown import markdown_table

    settings = [s for s in config.settings if s in set(table["setting"])]
    lines = [f"# Scoop convergence: {Path(output_dir).name}", "",
             f"Records: `{output_dir}` (one evaluation run per setting and variant). Scoop only; rates are "
             "episodes with Wilson 95 % intervals; the nudge moves every scoop action "
             f"{config.nudge.offset * 1000:g} mm (draws {', '.join(map(str, config.nudge.draws))}), its rate is the share of "
             "paired episodes whose spill during the scoop differs from the plain run's. Wall time is per episode on the "
             "machine that ran it.", ""]
    for method in dict.fromkeys(table["method"]):
        mine = table[table["method"] == method]
        rows = pd.concat([mine[mine["level"] == level] for level in dict.fromkeys(mine["level"])])  # by level, then setting
        header = ["Setting", "Level", "Episodes", *(name.capitalize() for name in RATES.values()), "Spilled (sum, mean)", "Scooped (sum, mean)",
                  "Over rim / off spoon particles", "Wall s"]
        body = []
        for _, r in rows.iterrows():
            body.append([f"{r['setting']} ({1 / r['time_step']:.0f} Hz, {r['solver_iterations']} it.)", r["level"], str(r["episodes"]),
                         *(format_rate(_rate_of(r, key)) for key in RATES),
                         f"{r['spilled_sum']}, {r['spilled_mean']:.2f}", f"{r['scooped_sum']}, {r['scooped_mean']:.1f}",
                         f"{r['spilled_scoop_over_rim_sum']} / {r['spilled_scoop_off_spoon_sum']}", f"{r['wall_time_s_mean']:.1f}"])
        choice = choose(table, list(config.settings), method, config.decision.max_half_width)
        lines += [f"## {method}", "", markdown_table(header, body), "", choice.sentence(config.decision.max_half_width), ""]
    missing = [s for s in config.settings if s not in settings]
    if missing:
        lines += [f"Settings without plain episodes yet: {', '.join(missing)}.", ""]
    return "\n".join(lines)


def write_summary(output_dir: str | Path, summary_to: str | Path) -> list[Path]:
    """Write convergence.csv, README.md and study.yaml under `summary_to`; returns the files."""
    from grits_lab.io import ensure_writable_dir, write_text_atomic

    table, config = convergence_table(output_dir)
    out = ensure_writable_dir(summary_to)
    text = summary_markdown(table, config, output_dir)
    files = [out / SUMMARY_FILE, out / "README.md", out / STUDY_FILE]
    write_text_atomic(files[0], table.to_csv(index=False))
    write_text_atomic(files[1], text + "\n")
    write_text_atomic(files[2], (Path(output_dir) / STUDY_FILE).read_text())
    return files
