"""Real-robot trials as a CSV file, read beside simulated runs so that one table compares them.

The schema (one row per trial, or one aggregate row standing for `trials` trials):

    method         a method name of the records (dp, grits, ...; grits_lab/report/vocabulary.py)
    food           food name, or `all` for an aggregate over foods
    level          quantity level, or `all`
    trial          trial index within (method, food, level); empty on an aggregate row
    task_success   per trial: true/false (or 1/0); aggregate: how many of `trials` succeeded
    spillage       the same for spillage
    scoop_failure  the same for scoop failure
    trials         optional: empty or 1 for one trial; N > 1 for an aggregate row of N trials
    source         optional: who ran the trials, e.g. `our lab`; default: the file's name

An outcome left empty is not stated (the paper gives no task success for DP (Post.)): it counts
towards no rate. The paper's own numbers ship as such a file (`paper_real_robot.csv` here), as
aggregate rows: the paper reports rates over 100 trials per method, not per-trial outcomes.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Collection, Sequence

import pandas as pd

from grits_lab.errors import InputError
from grits_lab.records import OUTCOME_COLUMNS


def canonical_name(name: object) -> str:
    """`Red Bean`, `red-bean` and `red_bean` name the same food; records may use any of them."""
    return str(name).strip().lower().replace(" ", "_").replace("-", "_")

REAL_COLUMNS = ("method", "food", "level", "trial", *OUTCOME_COLUMNS)
OPTIONAL_COLUMNS = ("trials", "source")
PAPER_FILE = Path(__file__).with_name("paper_real_robot.csv")
PAPER_SOURCE = "paper"


ALL = "all"  # food or level of an aggregate row over every food or level


def read_real_trials(path: str | Path, methods: Collection[str] | None = None) -> pd.DataFrame:
    """The trials of `path` as rows of (source, method, food, level, trials, <outcome>_k); InputError,
    one line naming the file (and line), on a bad file: a missing or unknown column, a method not in
    `methods` (when given), a row of one trial without its `trial` index or listed twice, outcomes
    no trial can have together (task success with spillage or scoop failure), or a lab's file whose
    source would be `paper` (the shipped paper numbers' name)."""
    path = Path(path)
    try:
        raw = pd.read_csv(path, dtype=str, keep_default_na=False)
    except (OSError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read real-robot trials {path}: {exc}") from None
    missing = [c for c in REAL_COLUMNS if c not in raw.columns]
    if missing:
        raise InputError(f"{path}: real-robot trials lack the columns {', '.join(missing)} (schema: grits_lab/report/real_trials.py)")
    unknown = [c for c in raw.columns if c not in REAL_COLUMNS + OPTIONAL_COLUMNS]
    if unknown:
        raise InputError(f"{path}: unknown column `{unknown[0]}`; the columns are {', '.join(REAL_COLUMNS + OPTIONAL_COLUMNS)}")
    rows, seen = [], {}
    for line, row in enumerate(raw.to_dict("records"), start=2):
        where = f"{path}:{line}"
        method = row["method"].strip()
        if not method:
            raise InputError(f"{where}: `method` is empty")
        if methods is not None and method not in methods:
            raise InputError(f"{where}: unknown method `{method}`; one of {', '.join(sorted(methods))}")
        source = row.get("source", "").strip() or path.stem
        if source == PAPER_SOURCE and path.resolve() != PAPER_FILE.resolve():
            raise InputError(f"{path}: the source `{PAPER_SOURCE}` is the name of the paper's shipped numbers; add a "
                             "`source` column naming who ran the trials (e.g. `our lab`), or rename the file")
        food, level = canonical_name(row["food"]) or ALL, row["level"].strip().lower() or ALL
        trials = _count(row.get("trials", ""), where, "trials", 1) or 1
        out = {"source": source, "method": method, "food": food, "level": level, "trials": trials}
        if trials == 1:
            trial = _count(row["trial"], where, "trial", 0)
            if trial is None:
                raise InputError(f"{where}: `trial` is empty on a row of one trial; number the trials of each "
                                 "(method, food, level), or give `trials` for an aggregate row")
            key = (source, method, food, level, trial)
            if key in seen:
                raise InputError(f"{where}: trial {trial} of {method} on {food} {level} is listed already on line {seen[key]}")
            seen[key] = line
        for outcome in OUTCOME_COLUMNS:
            out[f"{outcome}_k"] = _outcome(row[outcome], where, outcome, trials)
        for other in ("spillage", "scoop_failure"):
            success, failed = out["task_success_k"], out[f"{other}_k"]
            if success + failed > trials:  # NaN (not stated) compares False
                raise InputError(f"{where}: a trial with `task_success` cannot have `{other}`" if trials == 1 else
                                 f"{where}: `task_success` {success:.0f} and `{other}` {failed:.0f} add up to more than "
                                 f"{trials} trials; a successful trial has neither spillage nor a scoop failure")
        rows.append(out)
    return pd.DataFrame(rows, columns=["source", "method", "food", "level", "trials", *(f"{o}_k" for o in OUTCOME_COLUMNS)])


def read_real_files(paths: Sequence[str | Path], methods: Collection[str] | None = None) -> list[pd.DataFrame]:
    """`read_real_trials` of each file, each counted once: InputError for a file given twice, or two
    files holding trials of one source (name it with a `source` column)."""
    frames, sources = [], {}
    for i, path in enumerate(map(Path, paths)):
        if any(path.resolve() == Path(p).resolve() for p in paths[:i]):
            raise InputError(f"{path}: the real-robot trials file is given twice; give each file once")
        frame = read_real_trials(path, methods)
        for source in frame["source"].unique():
            if source in sources:
                raise InputError(f"{sources[source]} and {path} both hold trials of the source `{source}`; give each "
                                 "lab's file a `source` column of its own")
            sources[source] = path
        frames.append(frame)
    return frames


def _count(text: str, where: str, column: str, least: int) -> int | None:
    text = text.strip()
    if not text:
        return None
    try:
        value = int(text)
    except ValueError:
        raise InputError(f"{where}: `{column}` must be a whole number, got {text!r}") from None
    if value < least:
        raise InputError(f"{where}: `{column}` must be at least {least}, got {value}")
    return value


def _outcome(text: str, where: str, column: str, trials: int) -> float:
    """Trials with the outcome (NaN: not stated); a single trial may say true/false."""
    lowered = text.strip().lower()
    if lowered in ("", "nan"):
        return math.nan
    if trials == 1 and lowered in ("true", "yes", "false", "no"):
        return float(lowered in ("true", "yes"))
    value = _count(lowered, where, column, 0)
    assert value is not None
    if value > trials:
        raise InputError(f"{where}: `{column}` counts {value} of {trials} trials"
                         + ("; one trial is 0/1 or true/false" if trials == 1 else ""))
    return float(value)


def real_counts(trials: pd.DataFrame) -> pd.DataFrame:
    """Per (source, method): n and k of each outcome over the trials that state it, and `pairs`: the
    (food, level) pairs of its trials (`all` for an aggregate over foods or levels)."""
    rows = []
    for (source, method), group in trials.groupby(["source", "method"], sort=False):
        row = {"source": source, "method": method, "pairs": tuple(sorted(set(zip(group["food"], group["level"]))))}
        for outcome in OUTCOME_COLUMNS:
            stated = group[group[f"{outcome}_k"].notna()]
            row[f"{outcome}_k"] = int(stated[f"{outcome}_k"].sum())
            row[f"{outcome}_n"] = int(stated["trials"].sum())
        rows.append(row)
    return pd.DataFrame(rows)


def paper_rates() -> dict[str, dict[str, float]]:
    """The paper's real-robot rates per method from the shipped file: only outcomes the paper states."""
    counts = real_counts(read_real_trials(PAPER_FILE))
    return {row["method"]: {o: row[f"{o}_k"] / row[f"{o}_n"] for o in OUTCOME_COLUMNS if row[f"{o}_n"]}
            for row in counts.to_dict("records")}
