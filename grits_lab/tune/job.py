"""One sweep job: open (or resume, or join) the study, run the remaining trials, write the outputs."""

from __future__ import annotations

import dataclasses
import sys
from typing import Any

from grits_lab.tune.study_config import StudyConfig


def run_sweep(config: StudyConfig, n_trials: int | None = None, storage: str | None = None,
              report_only: bool = False, plots: bool = True, progress: bool = True) -> dict[str, Any]:
    """Run the study described by `config` to its trial budget and return the outputs' summary.

    `n_trials` and `storage` override the config's values; the methods of `config.reference` run
    first where their records are not stored yet (grits_lab/tune/reference.py); with `report_only`
    nothing runs and the tables, best.yaml and plots are rewritten from the storage and the records.
    """
    import optuna

    from grits_lab.errors import StorageError
    from grits_lab.io import ensure_writable_dir
    from grits_lab.tune.grits_binding import GritsEvaluator
    from grits_lab.tune.objective import make_evaluator
    from grits_lab.tune.outputs import write_outputs
    from grits_lab.tune.reference import carry_references, run_references
    from grits_lab.tune.storage import open_storage
    from grits_lab.tune.study import EVALUATOR_ATTR, open_study, run_trials
    from grits_lab.tune.synthetic import SyntheticEvaluator

    if n_trials is not None:
        config = dataclasses.replace(config, n_trials=n_trials)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    # The evaluator is built before the storage is touched: a missing evaluation layer or
    # checkpoint fails at once, without leaving an empty study behind.
    evaluator = None if report_only else make_evaluator(config)
    storage_obj, where = open_storage(storage or config.storage, config.study_dir / "journal.log")
    out_dir = ensure_writable_dir(config.study_dir)
    if report_only:
        try:
            study = optuna.load_study(study_name=config.study_name, storage=storage_obj)
        except KeyError:
            raise StorageError(f"no study named `{config.study_name}` in {where}") from None
        kind = study.user_attrs.get(EVALUATOR_ATTR, config.evaluator)
        label = SyntheticEvaluator.label if kind == "synthetic" else GritsEvaluator.label_for(config.evaluation.method)
    else:
        assert evaluator is not None
        study = open_study(config, storage_obj)
        label = evaluator.label
        print(f"sweep {config.study_name}: {label}; storage {where}; "
              f"{len(config.episodes())} episodes per trial; study budget {config.n_trials} trials",
              file=sys.stderr)
        try:
            run_references(config, evaluator, out_dir / "records")
            carry_references(study, config, out_dir / "records")
            run_trials(config, study, storage_obj, evaluator, records_dir=out_dir / "records",
                       progress=progress,
                       after_trial=lambda st: write_outputs(st, config, out_dir, where, label, plots=False))
        finally:
            evaluator.close()
    return write_outputs(study, config, out_dir, where, label, plots=plots)
