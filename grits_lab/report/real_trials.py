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

import pandas as pd

from grits_lab.errors import InputError
from grits_lab.records import OUTCOME_COLUMNS

REAL_COLUMNS = ("method", "food", "level", "trial", *OUTCOME_COLUMNS)
OPTIONAL_COLUMNS = ("trials", "source")
PAPER_FILE = Path(__file__).with_name("paper_real_robot.csv")
PAPER_SOURCE = "paper"


def read_real_trials(path: str | Path) -> pd.DataFrame:
    """The trials of `path` as rows of (source, method, trials, <outcome>_k); InputError, one line, on a bad file."""
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
    rows = []
    for line, row in enumerate(raw.to_dict("records"), start=2):
        where = f"{path}:{line}"
        method = row["method"].strip()
        if not method:
            raise InputError(f"{where}: `method` is empty")
        trials = _count(row.get("trials", ""), where, "trials", 1) or 1
        out = {"source": row.get("source", "").strip() or path.stem, "method": method, "trials": trials}
        for outcome in OUTCOME_COLUMNS:
            out[f"{outcome}_k"] = _outcome(row[outcome], where, outcome, trials)
        rows.append(out)
    return pd.DataFrame(rows, columns=["source", "method", "trials", *(f"{o}_k" for o in OUTCOME_COLUMNS)])


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
    """Per (source, method): n and k of each outcome over the trials that state it."""
    rows = []
    for (source, method), group in trials.groupby(["source", "method"], sort=False):
        row = {"source": source, "method": method}
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
