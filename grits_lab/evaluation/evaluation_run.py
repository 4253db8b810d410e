"""`grits-lab evaluate`: methods x foods x levels x trials fanned out over the runners, records to Parquet, resumable.

Run directory (the report layer's contract, docs/report.md): `episodes.parquet` (one row per
finished episode, rewritten atomically every `flush_every` episodes and at the end),
`config.yaml` (the resolved config) and `provenance.json` (code version, checkpoint digests,
episode plan). Running the same config again skips every episode already in `episodes.parquet`,
identified by (method, food, level, trial, seed, rho, s), and only runs the rest; records made with
other checkpoint files (digests) than the config's are refused, never resumed. One `evaluate` writes
a run directory at a time (grits_lab.io.exclusive_directory); runs one after another merge, and
config.yaml and provenance.json describe every method in the records.

Every method sees the same episode seeds, derive_seed(root, food, level, trial), so a difference
between methods is the method's and not the luck of the draw.
"""

from __future__ import annotations

import datetime as _dt
import math
import platform
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Iterable

import pandas as pd
import yaml
from tqdm import tqdm

from grits_lab.config import config_fingerprint, config_to_dict
from grits_lab.errors import InputError, StorageError
from grits_lab.evaluation.evaluation_config import EvaluationConfig, load_evaluation_config
from grits_lab.evaluation.task_episode import evaluation_episode
from grits_lab.evaluation.grid import EpisodeKey
from grits_lab.policies.control import NO_HOOK_COLUMNS, ScoopHook
from grits_lab.evaluation.methods import (
    METHODS, check_method_checkpoints, file_digest, guidance_columns, guidance_gap, method_checkpoints, method_spec,
    checkpoint_identity,
)
from grits_lab.io import ensure_writable_dir, exclusive_directory, save_parquet_atomic, write_json_atomic, write_text_atomic
from grits_lab.records import CODE_COMMIT, CPU_KERNELS, RECORD_COLUMNS, error_text, has_error, with_protocol
from grits_lab.runners import EpisodeResult, EpisodeSpec, make_executor
from grits_lab.runners.base import Executor
from grits_lab.runners.executor_config import check_reachable, cluster_address
from grits_lab.versions import PROTOCOL

RECORDS_FILE = "episodes.parquet"
IDENTITY = ("method", "food", "level", "trial", "seed", "rho", "s")


@dataclass
class EpisodeParams:
    """What a worker needs for one evaluation episode besides the spec's seed, food and level."""

    run_id: str
    method: str
    trial: int
    split: str
    config: EvaluationConfig
    paths: dict[str, str]
    digests: dict[str, str]
    hook: ScoopHook | None = None  # perturbs the scoop from outside (grits_lab/policies/control.py); None: none


def episode_keys(config: EvaluationConfig) -> list[EpisodeKey]:
    """Every (food, level, trial) of the config, with seeds derived from the root seed (EpisodeGrid.keys)."""
    from grits_lab.sim.foods import load_foods

    return config.keys(load_foods(config.sim.foods_file))


def identity_of(row: dict[str, Any]) -> tuple:
    rho = row["rho"]
    rho_text = "nan" if rho is None or (isinstance(rho, float) and math.isnan(rho)) else f"{float(rho):.6g}"
    return (str(row["method"]), str(row["food"]), str(row["level"]), int(row["trial"]), int(row["seed"]), rho_text, int(row["s"]))


def build_specs(config: EvaluationConfig, keys: Iterable[EpisodeKey], methods: list[str] | None = None,
                paths: dict[str, dict[str, str]] | None = None, digests: dict[str, str] | None = None,
                hook: ScoopHook | None = None) -> list[EpisodeSpec]:
    """Specs for methods x keys, method outermost in the list but interleaved by episode for early
    comparisons; every episode's scoop hooked by `hook` (None: none)."""
    methods = methods or list(config.methods)
    paths = paths if paths is not None else {m: method_checkpoints(m, config.checkpoints) for m in methods}
    digests = digests if digests is not None else checkpoint_digests(paths)
    specs = []
    for key in keys:
        for method in methods:
            params = EpisodeParams(config.run_id, method, key.trial, key.split, config, paths[method],
                                   {k: digests[p] for k, p in paths[method].items()}, hook)
            specs.append(EpisodeSpec(
                episode_id=f"{method}-{key.food}-{key.level}-{key.trial}", work=evaluation_episode, seed=key.seed,
                food=key.food, level=key.level, params={"evaluation": params},
            ))
    return specs


def checkpoint_digests(paths: dict[str, dict[str, str]]) -> dict[str, str]:
    files = sorted({p for by_key in paths.values() for p in by_key.values()})
    return {p: file_digest(p) for p in files}


def failed_episode_record(spec: EpisodeSpec, error: str, wall_time_s: float) -> dict[str, Any]:
    """The record of an episode that raised or whose worker died: every outcome False, the error kept,
    and the run's scoop hook columns (`ScoopHook.record_columns`), so that resuming the run finds
    every record made under its own settings."""
    p: EpisodeParams = spec.params["evaluation"]
    rho, s = guidance_columns(p.method, p.config)
    return {
        "run_id": p.run_id, "method": p.method, "food": spec.food, "split": p.split, "level": spec.level,
        "trial": p.trial, "seed": spec.seed, "task_success": False, "spillage": False, "scoop_failure": False,
        "scoop_success": False, "spilled_before_scoop": False, "n_particles": -1, "spilled": -1, "scooped": -1,
        "transferred": -1, "rho": rho, "s": s, "error": error or "unknown error", "wall_time_s": wall_time_s,
        **(p.hook or ScoopHook()).record_columns(), **{f"checkpoint_{k}": d for k, d in p.digests.items()},
    }


def result_record(result: EpisodeResult, code_commit: str | None = None) -> dict[str, Any]:
    """The episode's record, stamped with the task protocol this code runs (grits_lab/versions.py) and,
    where given, the driver's code commit (`code_commit`, grits_lab/records.py)."""
    assert result.spec is not None
    record = dict(result.payload) if result.ok else failed_episode_record(result.spec, result.error, result.wall_time_s)
    return {**record, "protocol": PROTOCOL, **({CODE_COMMIT: code_commit} if code_commit is not None else {})}


def records_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """Rows -> DataFrame with the record columns first, in a stable order (method, food, level, trial)."""
    frame = pd.DataFrame(rows)
    if frame.empty:
        return pd.DataFrame(columns=list(RECORD_COLUMNS))
    for column in RECORD_COLUMNS:
        if column not in frame.columns:
            frame[column] = None
    extra = sorted(c for c in frame.columns if c not in RECORD_COLUMNS)
    frame = frame[list(RECORD_COLUMNS) + extra]
    frame["error"] = error_text(frame["error"])
    return frame.sort_values(["method", "food", "level", "trial"], kind="stable").reset_index(drop=True)


ROLLOUT_CHUNKS_DIR = "rollout_chunks"


def write_rollout_chunks(out: Path, record: dict[str, Any], episode: dict[str, Any]) -> Path:
    """Write one episode's scoop chunks into `out/rollout_chunks/<method>/`, a spillage-kind dataset
    that `grits-lab compare-predictors --held-out` scores. The now stale index is removed; the first
    reader rebuilds it from the episode files (`grits_lab.data.format.load_index`)."""
    from grits_lab.data.format import INDEX_FILE, MANIFEST_FILE, write_episode

    dataset = out / ROLLOUT_CHUNKS_DIR / str(record["method"])
    if not (dataset / MANIFEST_FILE).exists():
        dataset.mkdir(parents=True, exist_ok=True)
        write_text_atomic(dataset / MANIFEST_FILE, yaml.safe_dump({
            "kind": "spillage", "format_version": 1, "status": "complete", "source": "policy rollouts",
            "protocol": PROTOCOL, "run_id": record.get("run_id"), "method": record["method"],
            "config": {"n_action_steps": int(episode["meta"]["n_action_steps"])},
        }, sort_keys=False))
    episode_id = f"{record['method']}-{record['food']}-{record['level']}-{int(record['trial'])}"
    meta = {**episode["meta"], "method": record["method"], "trial": int(record["trial"])}
    path = write_episode(dataset, episode_id, episode["arrays"], meta)
    (dataset / INDEX_FILE).unlink(missing_ok=True)
    return path


def run_specs(specs: list[EpisodeSpec], executor: Executor, progress: bool = True, done: list[dict[str, Any]] | None = None,
              on_flush: Any = None, flush_every: int = 4, desc: str = "evaluate", on_chunks: Any = None) -> list[dict[str, Any]]:
    """Run specs on `executor`; `on_flush(rows)` is called every `flush_every` results and at the end;
    `on_chunks(record, episode)` receives each record's rollout chunks (dropped from the record).
    Each new record names the code commit this driver runs (`code_commit`)."""
    from grits_lab.versions import git_commit

    rows = list(done or [])
    commit = git_commit()
    bar = tqdm(total=len(specs), desc=desc, disable=not progress, dynamic_ncols=True)
    since = 0
    try:
        for result in executor.map_unordered(specs):
            record = result_record(result, commit)
            chunks = record.pop("_chunks", None)
            if chunks is not None and on_chunks is not None:
                on_chunks(record, chunks)
            rows.append(record)
            since += 1
            bar.update(1)
            if not result.ok:
                bar.write(f"episode {result.episode_id} failed: {result.error}")
            if on_flush is not None and since >= flush_every:
                on_flush(rows)
                since = 0
    finally:
        bar.close()
        if on_flush is not None and since:
            on_flush(rows)
    return rows


def _load_existing(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    try:
        frame = pd.read_parquet(path)
    except Exception as exc:  # pyarrow raises many types on a damaged file
        raise StorageError(f"cannot read {path} to resume: {exc}; move it away to start over") from None
    return with_protocol(frame).to_dict("records")


def _refuse_other_protocol(records_path: Path, done: list[dict[str, Any]]) -> None:
    """Records of another task protocol are not resumed under this one (a run directory holds one
    protocol): InputError naming both and the way out."""
    other = sorted({str(r["protocol"]) for r in done} - {PROTOCOL})
    if other:
        raise InputError(f"{records_path} holds episodes of protocol {other[0]}, but this code runs {PROTOCOL} (docs/protocol.md); "
                         "rerun with --restart to discard them, or choose another output_dir")


def _refuse_other_checkpoints(records_path: Path, done: list[dict[str, Any]], paths: dict[str, dict[str, str]],
                              digests: dict[str, str]) -> None:
    """A method's records made with other checkpoint files than the config's now are not resumed
    under the new ones: InputError naming the key, both digests and the way out."""
    for method, by_key in paths.items():
        for key, path in by_key.items():
            recorded = {str(r.get(f"checkpoint_{key}")) for r in done if r["method"] == method and _present(r.get(f"checkpoint_{key}"))}
            other = sorted(recorded - {digests[path]})
            if other:
                raise InputError(
                    f"{records_path} holds `{method}` episodes made with `checkpoints.{key}` digest {other[0]}, but "
                    f"{path} has digest {digests[path]}; rerun with --restart to discard the records, or choose another output_dir")


def _without_unstated_failures(done: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records less those of failed episodes that name no scoop hook columns: earlier code wrote
    none on a failed record, so the setting it failed under is unknown. They are run again (and
    their rows replaced) instead of being taken as finished under whatever the run sets now."""
    columns = list(NO_HOOK_COLUMNS)
    if not done:
        return done
    failed = has_error(pd.Series([r.get("error") for r in done], dtype=object)).to_numpy()
    return [r for r, f in zip(done, failed) if not (f and not any(_present(r.get(c)) for c in columns))]


def _refuse_other_hook(records_path: Path, done: list[dict[str, Any]], hook: ScoopHook) -> None:
    """Records whose scoop ran under another hook (other `ScoopHook.record_columns`: a nudge, a branch
    of studies/outcome_sensitivity) are not resumed under this one: a run directory holds one; records
    from before the columns ran without any. InputError naming both."""
    want = hook.record_columns()

    def recorded(r: dict[str, Any]) -> tuple:
        return tuple(type(want[c])(r[c]) if _present(r.get(c)) else NO_HOOK_COLUMNS.get(c) for c in want)

    other = sorted({recorded(r) for r in done} - {tuple(want.values())}, key=str)
    if other:
        named = lambda values: ", ".join(f"{c} {v:g}" for c, v in zip(want, values))
        raise InputError(f"{records_path} holds episodes whose scoop ran with {named(other[0])}, but this run's scoop hook "
                         f"writes {named(want.values())}; choose another output_dir (or rerun with --restart to discard them)")


def other_kernels_note(records_path: Path, done: list[dict[str, Any]]) -> str:
    """A warning line when records of the run directory name other CPU kernels than this process's
    (`cpu_kernels`, grits_lab/versions.py), "" otherwise. A warning, not a refusal: a Ray cluster may
    mix CPUs. Episodes on other kernels are other draws of the same seeds (docs/evaluation.md "Other CPUs")."""
    from grits_lab.versions import cpu_kernels

    here = cpu_kernels()
    elsewhere = [label for r in done if _present(label := r.get(CPU_KERNELS)) and str(label) != here]
    if not elsewhere:
        return ""
    other = sorted(set(map(str, elsewhere)))
    return (f"warning: {len(elsewhere)} records in {records_path} ran on CPU kernels `{other[0]}`"
            f"{f' (and {len(other) - 1} other labels)' if len(other) > 1 else ''}, this machine runs `{here}`: the episodes "
            "added now are other draws of their seeds, not repeats (docs/evaluation.md \"Other CPUs\")")


def _present(value: Any) -> bool:
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def _earlier_run(out: Path, recorded_methods: list[str]) -> tuple[dict[str, Any], str | None]:
    """The provenance entries of methods already in the records, as an earlier run wrote them, and when
    the first run into the directory started (None without records or an earlier provenance.json)."""
    import json

    try:
        earlier = json.loads((out / "provenance.json").read_text())
    except (OSError, ValueError):
        return {}, None
    methods = earlier.get("methods", {}) if isinstance(earlier, dict) else {}
    started = earlier.get("started (UTC)") if isinstance(earlier, dict) and recorded_methods else None
    return ({m: methods[m] for m in recorded_methods if isinstance(methods, dict) and m in methods},
            started if isinstance(started, str) else None)


def provenance(config: EvaluationConfig, paths: dict[str, dict[str, str]], digests: dict[str, str], n_episodes: int,
               earlier: dict[str, Any] | None = None, first_started: str | None = None) -> dict[str, Any]:
    """What produced the records; `earlier`: entries of methods recorded by earlier runs into the same
    directory, kept (under the current entry where this run evaluates the method again);
    `first_started`: when the first of those runs started, kept as the directory's "started (UTC)".
    Each method evaluated now records when and at which code commit this run started it."""
    from grits_lab.versions import cpu_kernels, cpu_model, git_commit, package_versions

    now, commit = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S"), git_commit()

    # what a file digest cannot tell: whether two checkpoints on other paths hold the same model
    # (the training kernels only where the checkpoint recorded them)
    identity = {p: {key: value for key, value in checkpoint_identity(p).items() if value or key == "weights_sha256_16"}
                for by_key in paths.values() for p in by_key.values()}
    return {
        "run_id": config.run_id,
        "protocol": PROTOCOL,
        "started (UTC)": first_started or now,
        "code git commit": commit,  # the latest run's; each method's own is under "methods"
        "config fingerprint": config_fingerprint(config),
        "methods": {**(earlier or {}),
                    **{m: {"description": method_spec(m, config).description,
                           "checkpoints": {k: {"path": p, "sha256_16": digests[p], **identity[p]} for k, p in paths[m].items()},
                           "rho_s": list(guidance_columns(m, config)),
                           "started (UTC)": now, "code git commit": commit} for m in config.methods}},
        "guidance": config_to_dict(config.guidance),
        "posthoc": config_to_dict(config.posthoc),
        "root seed": config.seed,
        "seed rule": "derive_seed(root seed, food, level, trial), the same for every method",
        "episodes planned": n_episodes,
        "host": platform.node(),
        "cpu": cpu_model(),
        "cpu kernels": cpu_kernels(),  # the driver's; each record names its worker's (`cpu_kernels`)
        "packages": package_versions(),
    }


def evaluate(config: EvaluationConfig, *, progress: bool = True, restart: bool = False, executor: Executor | None = None,
             hook: ScoopHook | None = None) -> pd.DataFrame:
    """Run (or resume) the evaluation described by `config`; returns every record of the run directory.
    `hook` perturbs every episode's scoop from outside (grits_lab/policies/control.py `ScoopHook`);
    its `check(config)` runs first."""
    if hook is not None:
        hook.check(config)
    paths = {m: method_checkpoints(m, config.checkpoints) for m in config.methods}
    for method in config.methods:
        check_method_checkpoints(method, paths[method], config.guidance)
    keys = episode_keys(config)
    digests = checkpoint_digests(paths)
    specs = build_specs(config, keys, paths=paths, digests=digests, hook=hook)
    if executor is None:
        check_reachable(cluster_address(config.executor))
    out = ensure_writable_dir(config.output_dir)  # only once the run is known to be possible
    with exclusive_directory(out, "evaluate"):
        return _evaluate_in(out, config, specs, paths, digests, progress, restart, executor, hook)


def _evaluate_in(out: Path, config: EvaluationConfig, specs: list[EpisodeSpec], paths: dict[str, dict[str, str]],
                 digests: dict[str, str], progress: bool, restart: bool, executor: Executor | None,
                 hook: ScoopHook | None = None) -> pd.DataFrame:
    """`evaluate` once it holds the run directory: resume, write what describes the records, run the rest."""
    records_path = out / RECORDS_FILE
    done = [] if restart else _without_unstated_failures(_load_existing(records_path))
    _refuse_other_protocol(records_path, done)
    _refuse_other_checkpoints(records_path, done, paths, digests)
    _refuse_other_hook(records_path, done, hook or ScoopHook())
    recorded_methods = list(dict.fromkeys(str(r["method"]) for r in done))
    from grits_lab.evaluation.custom_methods import registered_methods

    known = {*METHODS, *registered_methods(config.custom_methods)}  # a lab's method no longer registered stays in provenance.json
    described = replace(config, methods=list(dict.fromkeys([*(m for m in recorded_methods if m in known), *config.methods])))
    write_text_atomic(out / "config.yaml", yaml.safe_dump(config_to_dict(described), sort_keys=False))
    earlier, first_started = _earlier_run(out, recorded_methods)
    write_json_atomic(out / "provenance.json", provenance(config, paths, digests, len(specs), earlier=earlier, first_started=first_started))
    if restart and records_path.exists():
        records_path.unlink()
    finished = {identity_of(r) for r in done}
    todo = []
    for spec in specs:
        p: EpisodeParams = spec.params["evaluation"]
        rho, s = guidance_columns(p.method, config)
        ident = identity_of({"method": p.method, "food": spec.food, "level": spec.level, "trial": p.trial, "seed": spec.seed, "rho": rho, "s": s})
        if ident not in finished:
            todo.append(spec)
    if progress and done:
        print(f"resuming {config.run_id}: {len(specs) - len(todo)} of {len(specs)} episodes already in {records_path}")
    if todo and (note := other_kernels_note(records_path, done)):
        print(note, file=sys.stderr)
    flush = lambda rows: save_parquet_atomic(records_path, records_frame(rows))
    if todo:
        own = executor is None
        executor = executor or make_executor(config.executor)
        try:
            run_specs(todo, executor, progress, done, flush, config.flush_every, desc=config.run_id,
                      on_chunks=(lambda record, episode: write_rollout_chunks(out, record, episode)) if config.rollout_chunks else None)
        finally:
            if own:
                executor.close()
    return pd.read_parquet(records_path) if records_path.exists() else records_frame([])


def evaluate_guidance(config: EvaluationConfig, keys: list[EpisodeKey], rho: float, s: int, method: str = "grits",
                      run_id: str = "sweep", executor: Executor | None = None, progress: bool = False,
                      paths: dict[str, str] | None = None, digests: dict[str, str] | None = None) -> pd.DataFrame:
    """The sweep's entry point: `method` of `config` with guidance rho, s (Algorithm 1) on `keys` -> their records.

    method: a guided built-in (grits*), or a registered controller whose class takes keyword
        arguments `rho` and `s` (grits_lab/evaluation/custom_methods.py), built with this rho and s.
    config: a loaded evaluation config; only its guidance's rho and s and the run id change, so
        every other guidance setting (gradient, step, clipping) is the evaluation's.
    keys: the episodes, with their own seeds (the sweep derives them from its own root, so no
        tuning episode is a test episode). Returns one record per episode (grits_lab/records.py
        columns). Nothing is written to disk: the sweep stores the returned records itself.
    executor: the pool to run on, left open (a sweep keeps one for all its trials, so its workers
        keep their simulators and loaded checkpoints); None: a pool made and closed here.
    paths, digests: the method's checkpoints ({key: path}) and their digests ({path: digest}) when
        the caller resolved them once; None: resolved from `config` here.
    Raises InputError for a method that takes no guidance (guidance_gap), before any episode runs.
    """
    gap = guidance_gap(method, config)
    if gap is not None:
        raise InputError(f"method {method!r} {gap}")
    config = replace(config, guidance=replace(config.guidance, rho=float(rho), s=int(s)))
    return evaluate_keys(config, keys, method, run_id=run_id, executor=executor, progress=progress, paths=paths, digests=digests)


def evaluate_keys(config: EvaluationConfig, keys: list[EpisodeKey], method: str, run_id: str = "sweep",
                  executor: Executor | None = None, progress: bool = False,
                  paths: dict[str, str] | None = None, digests: dict[str, str] | None = None) -> pd.DataFrame:
    """`method` of `config` as it is on `keys` -> one record per episode, nothing written to disk: a
    sweep's trials (through `evaluate_guidance`) and its `reference` methods (unguided DP on the
    validation episodes, say). `executor`, `paths` and `digests` as in `evaluate_guidance`."""
    config = replace(config, run_id=run_id)
    specs = build_specs(config, keys, methods=[method], paths=None if paths is None else {method: paths}, digests=digests)
    own = executor is None
    executor = executor or make_executor(config.executor)
    try:
        rows = run_specs(specs, executor, progress, desc=f"{run_id} {method}")
    finally:
        if own:
            executor.close()
    return records_frame(rows)


def evaluate_file(path: str | Path, overrides: dict[str, Any] | None = None, **kwargs: Any) -> pd.DataFrame:
    return evaluate(load_evaluation_config(path, overrides), **kwargs)


def failed_episodes_line(records: pd.DataFrame, records_path: str | Path) -> str | None:
    """One line for the records that hold an error (how many, and the first one's episode and error),
    or None when every episode ran; `grits-lab evaluate` prints it and exits 1."""
    if records.empty:
        return None
    failed = records[has_error(records["error"])]
    if failed.empty:
        return None
    first = failed.iloc[0]
    error = (str(first["error"]).strip().splitlines() or ["unknown error"])[0]
    return (f"{len(failed)} of {len(records)} episodes failed (records kept in {records_path}); the first, "
            f"{first['method']} on {first['food']} {first['level']} trial {first['trial']}: {error}")


def summary_table(records: pd.DataFrame) -> str:
    """Per method: episodes, errors, and rates with Wilson 95% intervals (the report layer's statistics)."""
    from grits_lab.intervals import wilson_interval

    if records.empty:
        return "no episodes"
    lines = [f"{'method':<16} {'n':>4} {'err':>4}  {'task success':<22} {'spillage':<22} {'scoop failure':<22}"]
    for method, rows in records.groupby("method", sort=False):
        errors = has_error(rows["error"])
        cells = []
        for column in ("task_success", "spillage", "scoop_failure"):
            k = int((rows[column].astype(bool) & ~errors).sum()) if column == "task_success" else int(rows[column].astype(bool).sum())
            lo, hi = wilson_interval(k, len(rows))
            cells.append(f"{k / len(rows):5.0%} [{lo:4.0%}, {hi:4.0%}]")
        lines.append(f"{method:<16} {len(rows):>4} {int(errors.sum()):>4}  " + " ".join(f"{c:<22}" for c in cells))
    return "\n".join(lines)
