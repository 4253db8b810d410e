"""A sweep's reference methods: run once on the validation episodes, every trial read against them.

A front of (rho, s) says which guidance settings beat each other, not whether any beats the
policy without guidance. A sweep file's `reference: [dp]` runs unguided Diffusion Policy (or any
method the evaluation config can run, as that config has it) once on the same validation
episodes, the same seeds, and keeps its records beside the trials' as
`records/reference_<method>.parquet`. The outputs then give each trial's episodes paired with the
reference's (`reference.csv`, the `reference` block of summary.json, the plot's marker): per
outcome, the count in each, the episodes only one of them had, and the exact sign test on those.

The reference runs before the first trial of a sweep process that finds no stored records of it
(each process of a shared study that starts before the first has stored them runs it too). A
stored reference that covers the validation episodes is kept, so resuming never runs it again;
one that does not, or an unreadable file, is run again.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import pandas as pd

from grits_lab.errors import GritsError, InputError
from grits_lab.intervals import sign_test_p
from grits_lab.io import save_parquet_atomic
from grits_lab.tune.objective import EpisodeEvaluator, check_records, scored_outcomes, summarize_records
from grits_lab.tune.study import trial_records_path
from grits_lab.tune.study_config import StudyConfig

if TYPE_CHECKING:
    import optuna

REFERENCE_PREFIX = "reference_"
REFERENCE_FILE = "reference.csv"
# The record outcomes a trial is paired on: the sweep's objectives and the scoop failures behind them.
PAIRED_OUTCOMES = ("task_success", "spillage", "scoop_failure")
PAIR_KEYS = ("food", "level", "trial", "seed")


def reference_path(records_dir: Path, method: str) -> Path:
    """Where the records of reference `method` are kept: `records_dir/reference_<method>.parquet`."""
    return Path(records_dir) / f"{REFERENCE_PREFIX}{method}.parquet"


def stored_reference(path: Path, episodes: list) -> tuple[pd.DataFrame | None, str]:
    """(records, "") when `path` holds records of exactly `episodes`; otherwise (None, why not):
    no file, an unreadable one, or one of other episodes."""
    if not path.is_file():
        return None, "no stored records yet"
    try:
        records = pd.read_parquet(path)
    except Exception as exc:  # a damaged or foreign file: pyarrow's errors have no common base
        return None, f"{path} is not readable ({type(exc).__name__})"
    try:
        check_records(records, episodes)
    except InputError as exc:
        return None, f"{path} is not this sweep's validation set ({exc})"
    return records, ""


def run_references(config: StudyConfig, evaluator: EpisodeEvaluator, records_dir: Path,
                   log: Callable[[str], None] | None = None) -> list[str]:
    """Run each method of `config.reference` whose stored records do not cover the validation
    episodes (`stored_reference`); return the methods run here. A reference whose run raises is
    logged in one line and left for the next sweep command, and the trials go on; a GritsError
    (bad input) is raised."""
    log = log or (lambda text: print(text, file=sys.stderr, flush=True))
    episodes = config.episodes()
    ran = []
    for method in config.reference:
        path = reference_path(records_dir, method)
        stored, why = stored_reference(path, episodes)
        if stored is not None:
            continue
        if path.exists():
            log(f"reference {method}: {why}; running it again")
        start = time.perf_counter()
        try:
            records = evaluator.reference(method, run_id=f"{config.study_name}/reference-{method}")
            check_records(records, episodes)
        except GritsError:
            raise
        except Exception as exc:  # like a crashed trial: the study goes on
            log(f"reference {method} failed: {type(exc).__name__}: {exc}; the trials go on, and the next sweep "
                "command runs it again")
            continue
        save_parquet_atomic(path, records)
        m = summarize_records(records)
        log(f"reference {method}: success={m.success_rate:.2f} spillage={m.spillage_rate:.2f} "
            f"({m.n_episodes} episodes, {time.perf_counter() - start:.1f} s)")
        ran.append(method)
    return ran


REFERENCE_ATTR_PREFIX = "reference:"


def carry_references(study: "optuna.Study", config: StudyConfig, records_dir: Path) -> dict[str, dict]:
    """Store the rates of each stored reference (`load_references`) in the study itself, as user
    attribute `reference:<method>` ({success_rate, spillage_rate, scoop_failure_rate, n_episodes,
    n_errors} over the validation episodes), so that whoever reads the storage (optuna-dashboard,
    another machine's sweep) sees the unguided baseline beside the trials' objective values.
    Returns {method: rates}. Not part of the study's identity."""
    found, _ = load_references(config, records_dir)
    carried = {}
    for method, records in found.items():
        carried[method] = summarize_records(records).as_attrs()
        if study.user_attrs.get(REFERENCE_ATTR_PREFIX + method) != carried[method]:
            study.set_user_attr(REFERENCE_ATTR_PREFIX + method, carried[method])
    return carried


def load_references(config: StudyConfig, records_dir: Path) -> tuple[dict[str, pd.DataFrame], dict[str, str]]:
    """({method: records} of the configured references whose stored records cover the validation
    episodes, {method: why not} of the others)."""
    episodes = config.episodes()
    found, missing = {}, {}
    for method in config.reference:
        records, why = stored_reference(reference_path(records_dir, method), episodes)
        if records is None:
            missing[method] = why
        else:
            found[method] = records
    return found, missing


def _outcomes(records: pd.DataFrame) -> pd.DataFrame:
    """Per episode (indexed by PAIR_KEYS), the paired outcomes as the sweep scores them (`scored_outcomes`)."""
    frame = scored_outcomes(records)[list(PAIRED_OUTCOMES)]
    frame.index = pd.MultiIndex.from_frame(records[list(PAIR_KEYS)].astype({"trial": "int64", "seed": "int64"}))
    return frame


def paired_counts(reference: pd.DataFrame, trial: pd.DataFrame) -> dict[str, int | float]:
    """One trial's records against a reference's on the episodes both ran (same food, level, trial
    and seed): `paired`, and per outcome of PAIRED_OUTCOMES `<outcome>_reference`, `_trial` (episodes
    with it), `_only_reference`, `_only_trial` and `_p` (exact two-sided sign test on those two)."""
    ref, own = _outcomes(reference), _outcomes(trial)
    both = ref.add_suffix("_reference").join(own.add_suffix("_trial"), how="inner")
    row: dict[str, int | float] = {"paired": int(len(both))}
    for outcome in PAIRED_OUTCOMES:
        a, b = both[f"{outcome}_reference"], both[f"{outcome}_trial"]
        row.update({f"{outcome}_reference": int(a.sum()), f"{outcome}_trial": int(b.sum()),
                    f"{outcome}_only_reference": int((a & ~b).sum()), f"{outcome}_only_trial": int((b & ~a).sum())})
        row[f"{outcome}_p"] = sign_test_p(int(row[f"{outcome}_only_reference"]), int(row[f"{outcome}_only_trial"]))
    return row


def reference_table(references: dict[str, pd.DataFrame], records_dir: Path, trials: pd.DataFrame) -> pd.DataFrame:
    """One row per (reference method of `references`, the stored ones of `load_references`; completed
    trial with readable records in `records_dir`): the trial's number, rho, s and whether it is on the
    Pareto front (from `trials`, the trials table), then `paired_counts`. Empty without references."""
    rows = []
    if not references or trials.empty:
        return pd.DataFrame(rows)
    done = trials[trials["state"] == "COMPLETE"]
    for _, t in done.iterrows():
        try:
            records = pd.read_parquet(trial_records_path(records_dir, int(t["number"])))
        except Exception:  # missing or damaged: the trials table keeps its rates; nothing to pair
            continue
        for method, reference in references.items():
            rows.append({"reference": method, "trial": int(t["number"]), "rho": float(t["rho"]), "s": int(t["s"]),
                         "pareto_front": bool(t["pareto_front"]), **paired_counts(reference, records)})
    return pd.DataFrame(rows).sort_values(["reference", "trial"], kind="stable", ignore_index=True) if rows else pd.DataFrame()


def paired_line(row: pd.Series | dict, reference: str) -> str:
    """"task success 6 -> 9 (-1 +4, p 0.38); spillage ..." for one row of `reference_table`."""
    cells = [f"{outcome.replace('_', ' ')} {row[f'{outcome}_reference']} -> {row[f'{outcome}_trial']} "
             f"(-{row[f'{outcome}_only_reference']} +{row[f'{outcome}_only_trial']}, p {row[f'{outcome}_p']:.2g})"
             for outcome in PAIRED_OUTCOMES]
    return f"against {reference} on {row['paired']} paired episodes: " + "; ".join(cells)
