"""Find and read a run's evaluation records, sweep tables and provenance files into one RunData.

What the report expects in RUN_DIR (written by `grits-lab evaluate` and `grits-lab sweep`):

* episode records, one row per episode with the columns of grits_lab/records.py, as Parquet:
  `episodes.parquet`, or several `*.parquet` shards, directly in RUN_DIR or in RUN_DIR/records/
  or RUN_DIR/episodes/ (RUN_DIR may also be a single .parquet file), or as `episodes.csv` directly in
  RUN_DIR: a committed summary page (`--summary-to studies/STUDY/summaries/NAME`) is a run. Rows that appear in more
  than one file (a consolidated file beside its shards) are counted once. Records of further run
  directories can join them (`load_run(..., also=...)`, `grits-lab report RUN_DIR OTHER_RUN ...`).
* optional run metadata: `config.yaml` (and any other *.yaml at the top level) and
  `provenance.json`, shown verbatim in the report's provenance section.
* optional sweep outputs anywhere up to two folders below RUN_DIR: a trials table
  `trials.parquet` (preferred) or `trials.csv`, and beside it a best-parameters YAML (`best.yaml`,
  `best_params.yaml` or `best*.yaml`) and the trials paired with the sweep's reference methods
  (`reference.csv`).

Records are read, never re-scored: the only change made is that an episode with a non-empty
`error` has its task success set to False (it counts as a failure and is shown as a count).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import pandas as pd
import yaml

from grits_lab.config import parse_yaml
from grits_lab.errors import InputError, StorageError
from grits_lab.records import OUTCOME_COLUMNS, error_text, has_error, with_protocol
from grits_lab.report.vocabulary import canonical_name, method_display

REQUIRED_COLUMNS = ("method", "food", "level", *OUTCOME_COLUMNS)
FLAG_COLUMNS = (*OUTCOME_COLUMNS, "spilled_before_scoop")
RECORD_SUBDIRS = ("records", "episodes")
TRIALS_FILES = ("trials.parquet", "trials.csv")
SWEEP_REFERENCE_FILE = "reference.csv"  # beside the trials table
NOT_RECORD_FILES = {"trials.parquet", "index.parquet"}
PAGE_RECORDS_FILE = "episodes.csv"  # the records a summary page keeps (grits_lab/report/summary.py)
MAX_CONFIG_CHARS = 20_000
# Columns that identify one episode; a row seen twice with the same identity is a duplicate.
IDENTITY_COLUMNS = ("run_id", "protocol", "method", "food", "level", "trial", "seed", "rho", "s", "checkpoint_predictor")


@dataclass
class RunData:
    """Everything the report reads from a run directory."""

    run_dir: Path
    also_runs: list[Path] = field(default_factory=list)  # further run directories whose records joined RUN_DIR's
    episodes: pd.DataFrame | None = None
    episode_files: list[Path] = field(default_factory=list)
    ignored_files: list[str] = field(default_factory=list)
    duplicates_dropped: int = 0
    trials: pd.DataFrame | None = None
    trials_file: Path | None = None
    best_params: dict[str, Any] | None = None
    best_params_file: Path | None = None
    best_params_text: str = ""
    # A sweep's trials paired with its reference methods (`reference.csv`, grits_lab/tune/reference.py).
    sweep_reference: pd.DataFrame | None = None
    configs: dict[str, str] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)


def load_run(run_dir: str | Path, exclude: str | Path | None = None, also: Sequence[str | Path] = (),
             methods: Sequence[str] = ()) -> RunData:
    """Read RUN_DIR; `exclude` (the report's own output folder) is never searched for inputs.

    `also`: more run directories (or .parquet files) whose episode records join RUN_DIR's, e.g. a
    GRITS run at tuned (rho, s) beside the run with the paper's values; a method run at more than
    one (rho, s) is reported once per setting. Configs, provenance and sweep tables come from
    RUN_DIR only. Raises InputError, before anything is written, when a run is missing, given twice,
    inside the report's output folder, a sweep (with `also`), without records (in `also`), or when
    two runs hold the same episode of the same method at the same (rho, s).

    `methods`: keep only these methods' episodes (e.g. a run directory one of whose methods was
    stopped early); InputError when the records hold no episode of one of them.
    """
    run_dir = Path(run_dir)
    others = [Path(p) for p in also]
    excluded = Path(exclude).resolve() if exclude is not None else None
    _check_inputs([run_dir, *others], excluded)
    data = RunData(run_dir=run_dir)
    frames = _read_records(_record_files(run_dir, excluded), data)
    base = run_dir if run_dir.is_dir() else run_dir.parent
    data.trials_file = _find_trials(base, excluded)
    if others and data.trials_file is not None:
        raise InputError(f"{run_dir} is a sweep; several runs are reported together only as evaluation runs")
    sources = [(run_dir, frames)]
    for other in others:
        if _find_trials(other if other.is_dir() else other.parent, excluded) is not None:
            raise InputError(f"{other} is a sweep; give evaluation run directories after RUN_DIR")
        found = _read_records(_record_files(other, excluded), data)
        if not found:
            raise InputError(f"no episode records in {other}: expected episodes.parquet, *.parquet files or a summary page's episodes.csv with "
                             f"columns {', '.join(REQUIRED_COLUMNS)}")
        data.also_runs.append(other)
        sources.append((other, found))
        frames = frames + found
    if others:
        _check_disjoint(sources)
    if data.trials_file is not None:
        data.trials = _read_table(data.trials_file)
        data.best_params_file = _find_best_params(data.trials_file.parent)
        if data.best_params_file is not None:
            data.best_params = _read_yaml(data.best_params_file)
            data.best_params_text = data.best_params_file.read_text(errors="replace")
        if (data.trials_file.parent / SWEEP_REFERENCE_FILE).is_file():
            data.sweep_reference = _read_table(data.trials_file.parent / SWEEP_REFERENCE_FILE)
    if not frames and data.trials is None:
        detail = f"; ignored: {'; '.join(data.ignored_files)}" if data.ignored_files else ""
        raise InputError(
            f"no episode records in {run_dir}: expected episodes.parquet, *.parquet files or a summary page's episodes.csv with "
            f"columns {', '.join(REQUIRED_COLUMNS)} (or a sweep trials.parquet/trials.csv){detail}"
        )
    if frames:
        combined = pd.concat(frames, ignore_index=True)
        data.episodes, data.duplicates_dropped = _deduplicate(normalize_records(combined))
    if methods:
        data.episodes = _only_methods(data.episodes, methods)
    data.configs = _read_configs(base, data.trials_file, data.best_params_file)
    data.provenance = _read_provenance(base, data.trials_file)
    return data


def _only_methods(episodes: pd.DataFrame | None, methods: Sequence[str]) -> pd.DataFrame:
    """The episodes of `methods` only; InputError naming any method the records do not hold."""
    held = [] if episodes is None else sorted(episodes["method"].unique())
    if absent := [m for m in dict.fromkeys(methods) if m not in held]:
        raise InputError(f"--methods: the records hold no episode of {', '.join(absent)} (they hold: {', '.join(held) or 'none'})")
    assert episodes is not None
    return episodes[episodes["method"].isin(list(methods))].reset_index(drop=True)


def normalize_records(frame: pd.DataFrame) -> pd.DataFrame:
    """Typed copy of raw records, with `is_error`, `food_key` and the method `variant` added.

    A method evaluated at more than one guidance setting (rho, s), or guided by more than one
    predictor checkpoint (`checkpoint_predictor`, its digest), is split into variants, one per
    combination, so that rows from different settings or predictors are never pooled into one rate.
    Records of more than one task protocol (`protocol`, docs/protocol.md) label every variant with
    its protocol, so no table pools two protocols or shows them side by side unlabelled.
    """
    frame = frame.copy()
    if "protocol" not in frame.columns:
        frame = with_protocol(frame)
    missing = [c for c in REQUIRED_COLUMNS if c not in frame.columns]
    if missing:
        raise InputError(f"episode records lack required columns: {', '.join(missing)}")
    for column in ("method", "food", "level"):
        if frame[column].isna().any():
            raise InputError(f"episode records have {int(frame[column].isna().sum())} rows without `{column}`")
        frame[column] = frame[column].astype(str)
    if "error" not in frame.columns:
        frame["error"] = ""
    frame["is_error"] = has_error(frame["error"])
    frame["error"] = error_text(frame["error"]).str.strip()
    for column in FLAG_COLUMNS:
        if column in frame.columns:
            frame[column] = _to_flag(frame[column], column, frame["is_error"])
    frame.loc[frame["is_error"], "task_success"] = False
    frame["food_key"] = frame["food"].map(canonical_name)
    frame["rho"] = pd.to_numeric(frame["rho"], errors="coerce") if "rho" in frame.columns else math.nan
    frame["s"] = pd.to_numeric(frame["s"], errors="coerce").fillna(-1).astype(int) if "s" in frame.columns else -1
    frame["variant"], frame["variant_name"] = _variants(frame)
    return frame


def _to_flag(values: pd.Series, column: str, is_error: pd.Series) -> pd.Series:
    """Booleans from bool/0-1 columns; an unset flag is an input error unless the episode errored."""
    numeric = pd.to_numeric(values.map(lambda v: v if not isinstance(v, str) else _parse_bool(v, column)), errors="coerce")
    bad = numeric.notna() & ~numeric.isin([0, 1])
    if bad.any():
        raise InputError(f"`{column}` must be true/false; got {values[bad].iloc[0]!r} in {int(bad.sum())} rows")
    unset = numeric.isna() & ~is_error
    if unset.any():
        raise InputError(f"`{column}` is missing in {int(unset.sum())} episode records without an error")
    return numeric.fillna(0).astype(bool)


def _parse_bool(text: str, column: str) -> float:
    lowered = text.strip().lower()
    if lowered in ("true", "1", "yes"):
        return 1.0
    if lowered in ("false", "0", "no"):
        return 0.0
    if lowered in ("", "nan", "none", "null"):
        return math.nan
    raise InputError(f"`{column}` must be true/false; got {text!r}")


def _variants(frame: pd.DataFrame) -> tuple[pd.Series, pd.Series]:
    """Per row: the variant key and display name; a method recorded at more than one guidance setting
    (rho, s) or with more than one predictor checkpoint (its digest) gets one variant per combination,
    and when the records hold more than one task protocol every variant names its protocol."""
    variant = frame["method"].copy()
    name = frame["method"].map(method_display)
    predictor = frame["checkpoint_predictor"].astype(str) if "checkpoint_predictor" in frame.columns else pd.Series("", index=frame.index)
    by_protocol = frame["protocol"].nunique() > 1
    for method, rows in frame.groupby("method", sort=False):
        settings = rows[["rho", "s"]].drop_duplicates()
        predictors = predictor[rows.index]
        by_setting, by_predictor = len(settings) > 1, predictors.nunique() > 1
        if not (by_setting or by_predictor or by_protocol):
            continue
        digits = _label_digits(settings)
        for index, row in rows.iterrows():
            parts = [_setting_label(row["rho"], row["s"], digits)] if by_setting else []
            if by_predictor:
                parts.append(f"predictor {predictors[index][:8]}")
            if by_protocol:
                parts.append(str(row["protocol"]))
            label = ", ".join(parts)
            variant.at[index] = f"{method}[{label}]"
            name.at[index] = f"{method_display(method)} ({label})"
    return variant, name


def _label_digits(settings: pd.DataFrame) -> int:
    """The fewest significant digits of rho (3 or more) that keep every (rho, s) setting's label distinct."""
    for digits in range(3, 18):
        labels = {_setting_label(rho, s, digits) for rho, s in settings.itertuples(index=False)}
        if len(labels) == len(settings):
            return digits
    return 17


def _setting_label(rho: float, s: int, digits: int = 3) -> str:
    rho_text = "none" if pd.isna(rho) else f"{rho:.{digits}g}"
    return f"rho={rho_text}, s={int(s)}"


def _check_inputs(paths: list[Path], excluded: Path | None) -> None:
    seen: dict[Path, Path] = {}
    for path in paths:
        if not path.exists():
            raise InputError(f"run directory not found: {path}")
        resolved = path.resolve()
        if resolved in seen:
            raise InputError(f"{path} is given twice")
        seen[resolved] = path
        # The report writes into its output folder: an input that is that folder, or a file in it, could be overwritten.
        if excluded is not None and (resolved == excluded or (resolved.is_file() and excluded in resolved.parents)):
            raise InputError(f"{path} is, or lies in, the report's output directory {excluded}; choose another --output-dir")


# An episode of one method at one guidance setting, whatever run wrote it.
_EPISODE_KEY = tuple(c for c in IDENTITY_COLUMNS if c != "run_id")


def _check_disjoint(sources: list[tuple[Path, list[pd.DataFrame]]]) -> None:
    """Runs reported together must not hold the same episode twice (it would be counted twice or hidden)."""
    owner: dict[tuple, Path] = {}
    for path, frames in sources:
        keys = set()
        for frame in frames:
            columns = [c for c in _EPISODE_KEY if c in frame.columns]
            keys |= {tuple(zip(columns, row)) for row in frame[columns].astype(str).itertuples(index=False, name=None)}
        for key in sorted(keys):
            if key in owner:
                episode = ", ".join(f"{column}={value}" for column, value in key)
                raise InputError(f"{owner[key]} and {path} hold the same episode ({episode}); "
                                 "report runs that share an episode one at a time")
        owner.update(dict.fromkeys(keys, path))


def _read_records(files: list[Path], data: RunData) -> list[pd.DataFrame]:
    """The episode-record tables among `files`; the others are listed in `data.ignored_files`."""
    frames = []
    for path in files:
        frame = _read_table(path)
        missing = [c for c in REQUIRED_COLUMNS if c not in frame.columns]
        if missing:
            data.ignored_files.append(f"{path.name} (not episode records: lacks {', '.join(missing)})")
            continue
        data.episode_files.append(path)
        frames.append(_with_guiding_predictor(with_protocol(frame)))
    return frames


def _with_guiding_predictor(frame: pd.DataFrame) -> pd.DataFrame:
    """`checkpoint_predictor` set to the digest of whichever predictor guided each episode.

    Records keep one digest column per checkpoint key (`checkpoint_predictor`,
    `checkpoint_predictor_raw`, `checkpoint_predictor_pointnet2`, `checkpoint_predictor_horizon`); a method
    uses one of them.
    """
    columns = sorted(c for c in frame.columns if c.startswith("checkpoint_predictor"))
    if not columns:
        return frame
    frame = frame.copy()
    frame["checkpoint_predictor"] = frame[columns].bfill(axis=1).iloc[:, 0]
    return frame


def _deduplicate(frame: pd.DataFrame) -> tuple[pd.DataFrame, int]:
    keys = [c for c in IDENTITY_COLUMNS if c in frame.columns]
    if "trial" not in keys and "seed" not in keys:
        return frame.reset_index(drop=True), 0  # no episode identity to compare: keep every row
    identity = frame[keys].astype(str)
    duplicated = identity.duplicated(keep="first")
    return frame[~duplicated].reset_index(drop=True), int(duplicated.sum())


def _record_files(run_dir: Path, excluded: Path | None) -> list[Path]:
    if run_dir.is_file():
        if run_dir.suffix != ".parquet":
            raise InputError(f"expected a run directory, a summary page or a .parquet file of episode records, got {run_dir}")
        return [run_dir]
    folders = [run_dir] + [run_dir / sub for sub in RECORD_SUBDIRS if (run_dir / sub).is_dir()]
    files = []
    for folder in folders:
        if excluded is not None and folder.resolve() == excluded:
            continue
        files += sorted(
            p for p in folder.glob("*.parquet")
            if p.is_file() and not p.name.startswith(".") and p.name not in NOT_RECORD_FILES
        )
    if (run_dir / PAGE_RECORDS_FILE).is_file():
        files.append(run_dir / PAGE_RECORDS_FILE)
    # A consolidated episodes.parquet is read first, so its rows win over identical shard rows.
    return sorted(files, key=lambda p: (p.name != "episodes.parquet", str(p)))


def _find_trials(base: Path, excluded: Path | None) -> Path | None:
    for depth in range(3):
        for name in TRIALS_FILES:
            pattern = "/".join(["*"] * depth + [name])
            hits = sorted(
                p for p in base.glob(pattern)
                if excluded is None or excluded not in p.resolve().parents
            )
            if hits:
                return hits[0]
    return None


def _find_best_params(folder: Path) -> Path | None:
    candidates = [folder / "best_params.yaml", *sorted(folder.glob("best*.yaml")), *sorted(folder.glob("best*.yml"))]
    return next((p for p in candidates if p.is_file()), None)


def _read_table(path: Path) -> pd.DataFrame:
    try:
        if path.suffix == ".csv":
            return pd.read_csv(path)
        return pd.read_parquet(path)
    except Exception as exc:  # pyarrow and pandas raise many types for damaged files
        raise StorageError(f"cannot read {path}: {type(exc).__name__}: {exc}") from None


def _read_yaml(path: Path) -> dict[str, Any]:
    try:
        loaded = parse_yaml(path.read_text(), path)
    except (OSError, yaml.YAMLError) as exc:
        raise StorageError(f"cannot read {path}: {exc}") from None
    return loaded if isinstance(loaded, dict) else {"value": loaded}


def _read_configs(base: Path, *beside: Path | None) -> dict[str, str]:
    folders = [base] + [p.parent for p in beside if p is not None and p.parent != base]
    configs = {}
    for folder in dict.fromkeys(folders):
        for path in sorted([*folder.glob("*.yaml"), *folder.glob("*.yml")]):
            text = path.read_text(errors="replace")
            if len(text) > MAX_CONFIG_CHARS:
                text = text[:MAX_CONFIG_CHARS] + f"\n# ... truncated ({len(text)} characters in all)\n"
            configs[_relative(path, base)] = text
    return configs


def _read_provenance(base: Path, trials_file: Path | None) -> dict[str, Any]:
    folders = [base] + ([trials_file.parent] if trials_file is not None and trials_file.parent != base else [])
    provenance = {}
    for folder in folders:
        path = folder / "provenance.json"
        if path.is_file():
            try:
                provenance[_relative(path, base)] = json.loads(path.read_text())
            except (OSError, json.JSONDecodeError) as exc:
                raise StorageError(f"cannot read {path}: {exc}") from None
    return provenance


def _relative(path: Path, base: Path) -> str:
    try:
        return str(path.relative_to(base))
    except ValueError:
        return str(path)
