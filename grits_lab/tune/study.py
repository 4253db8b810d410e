"""Create or resume a study and run trials: ask, evaluate (rho, s), tell; recover dead workers' trials.

The loop is ask-and-tell so that the study's budget (`n_trials`) is shared by every process on
the storage and across restarts: a worker asks for a trial only while fewer than `n_trials`
trials are complete, failed or running. A trial whose evaluation raises is told FAIL with the
error kept in its attributes. A RUNNING trial whose worker is gone (the process no longer exists
on this host, or its heartbeat is older than `stale_after_s`) is marked FAIL and its parameters
are queued again, so a killed sweep loses neither history nor the interrupted point.
"""

from __future__ import annotations

import os
import socket
import sys
import threading
import time
import uuid
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import optuna
from optuna.exceptions import DuplicatedStudyError, UpdateFinishedTrialError
from optuna.storages import BaseStorage
from optuna.study import StudyDirection
from optuna.trial import FrozenTrial, TrialState

from grits_lab.errors import ConfigError, GritsError
from grits_lab.io import pid_alive, save_parquet_atomic
from grits_lab.tune.study_config import StudyConfig
from grits_lab.tune.objective import EpisodeEvaluator, check_records, objective_values, summarize_records
from grits_lab.tune.sampler import build_sampler

IDENTITY_ATTR = "grits:identity"
EVALUATOR_ATTR = "grits:evaluator"
WORKER_ATTR = "worker"
HEARTBEAT_ATTR = "heartbeat"
REQUEUED_ATTR = "requeued"  # a FAIL trial whose parameters were queued again (stale or interrupted)
RETRY_OF_ATTR = "retry_of"
ERROR_ATTR = "error"
ENQUEUED_ATTR = "enqueued"


@dataclass(frozen=True)
class WorkerIdentity:
    """Who runs a trial: host, process id and a token that tells apart a reused process id."""

    host: str
    pid: int
    token: str

    @classmethod
    def current(cls) -> "WorkerIdentity":
        return cls(socket.gethostname(), os.getpid(), uuid.uuid4().hex[:8])

    def encode(self) -> str:
        return f"{self.host}:{self.pid}:{self.token}"

    @classmethod
    def decode(cls, text: str) -> "WorkerIdentity | None":
        parts = str(text).rsplit(":", 2)
        if len(parts) != 3 or not parts[1].isdigit():
            return None
        return cls(parts[0], int(parts[1]), parts[2])


# What guidance did on a trial's validation plans (records.plan_guidance_effect), kept with the trial:
# the best point's tie-break (tune/outputs.py, `best_trial`) and a column optuna-dashboard shows.
GUIDANCE_ATTRS = {"p_spill_change": "relative_change", "displacement_mm": "displacement_mm"}


def guidance_attrs(records) -> dict[str, float]:
    """{p_spill_change, displacement_mm} of a trial's records, where they compared their plans with the
    unguided sample; empty otherwise."""
    from grits_lab.records import plan_guidance_effect

    effect = plan_guidance_effect(records)
    if effect is None:
        return {}
    return {attr: float(effect[key]) for attr, key in GUIDANCE_ATTRS.items() if effect[key] == effect[key]}


def trial_records_path(records_dir: Path, number: int) -> Path:
    """Where trial `number`'s episode records are kept: `records_dir/trial_NNNNN.parquet`."""
    return Path(records_dir) / f"trial_{number:05d}.parquet"


def open_study(config: StudyConfig, storage: BaseStorage) -> optuna.Study:
    """Create the study (queueing the configured defaults first) or load it and check it matches.

    The creator queues the defaults and then writes the study's attributes, the identity last. A
    worker that finds the identity missing waits `CREATOR_GRACE_S` for a creator still at work;
    if it is still missing, the creator died part-way and this worker finishes its job: the
    defaults are queued where no trial holds them yet, and the attributes are written.
    """
    directions = [StudyDirection.MAXIMIZE if d == "maximize" else StudyDirection.MINIMIZE
                  for d in config.objective.directions]
    sampler = build_sampler(config.sampler, config.objective.max_spillage)
    try:
        storage.create_new_study(directions, config.study_name)
        created = True
    except DuplicatedStudyError:
        created = False
    study = optuna.load_study(study_name=config.study_name, storage=storage, sampler=sampler)
    if not created:
        deadline = time.monotonic() + CREATOR_GRACE_S
        while IDENTITY_ATTR not in study.user_attrs and time.monotonic() < deadline:
            time.sleep(0.1)
    if (created or IDENTITY_ATTR not in study.user_attrs) and \
            [d.name.lower() for d in study.directions] == config.objective.directions:
        _finish_creation(study, config)
    return _checked(study, config)


# How long a worker that joins a study without an identity waits for its creator to write it.
CREATOR_GRACE_S = 5.0


def _finish_creation(study: optuna.Study, config: StudyConfig) -> None:
    """Queue the defaults that no trial holds yet, then write the attributes, the identity last."""
    for point in config.enqueue:
        study.enqueue_trial({"rho": point.rho, "s": point.s},
                            user_attrs={ENQUEUED_ATTR: True}, skip_if_exists=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        study.set_metric_names(config.objective.value_names)
    study.set_user_attr(EVALUATOR_ATTR, config.evaluator)
    study.set_user_attr(IDENTITY_ATTR, config.identity())


def _checked(study: optuna.Study, config: StudyConfig) -> optuna.Study:
    if [d.name.lower() for d in study.directions] != config.objective.directions:
        raise ConfigError(
            f"study `{config.study_name}` exists with objective directions "
            f"{[d.name.lower() for d in study.directions]}, but this config asks for "
            f"{config.objective.directions}; choose another `study_name`"
        )
    if study.user_attrs.get(IDENTITY_ATTR) != config.identity():
        raise ConfigError(
            f"study `{config.study_name}` was created with a different search space, objective, "
            f"episode set or evaluator; resume it with its original sweep file or choose another `study_name`"
        )
    return study


def _trial_id(study: optuna.Study, storage: BaseStorage, number: int) -> int:
    return storage.get_trial_id_from_study_id_trial_number(storage.get_study_id_from_name(study.study_name), number)


def stale_reason(trial: FrozenTrial, me: WorkerIdentity, stale_after_s: float, now: float) -> str | None:
    """Why a RUNNING trial is taken as abandoned, or None while its worker may still be alive."""
    worker = WorkerIdentity.decode(trial.user_attrs.get(WORKER_ATTR, ""))
    if worker is not None and worker.host == me.host and worker.token != me.token:
        if worker.pid == me.pid or not pid_alive(worker.pid):
            return f"worker process {worker.pid} on {worker.host} is gone"
    last = trial.user_attrs.get(HEARTBEAT_ATTR)
    if last is None and trial.datetime_start is not None:
        last = trial.datetime_start.timestamp()
    if last is not None and now - float(last) > stale_after_s:
        return f"no heartbeat for {now - float(last):.0f} s"
    return None


def recover_stale_trials(study: optuna.Study, storage: BaseStorage, stale_after_s: float,
                         me: WorkerIdentity, log: Callable[[str], None] = print) -> list[int]:
    """Mark abandoned RUNNING trials FAIL and queue their parameters again; return their numbers.

    Two workers may find the same stale trial; only the one whose FAIL transition succeeds
    queues the retry, so the point is run once.
    """
    recovered = []
    now = time.time()
    for trial in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        reason = stale_reason(trial, me, stale_after_s, now)
        if reason is None:
            continue
        trial_id = _trial_id(study, storage, trial.number)
        try:
            storage.set_trial_user_attr(trial_id, REQUEUED_ATTR, True)
            storage.set_trial_user_attr(trial_id, ERROR_ATTR, f"abandoned: {reason}")
            storage.set_trial_state_values(trial_id, TrialState.FAIL)
        except UpdateFinishedTrialError:
            continue  # finished meanwhile, by its worker or by another recovering worker
        params = trial.system_attrs.get("fixed_params") or trial.params
        if {"rho", "s"} <= set(params):
            study.enqueue_trial({"rho": params["rho"], "s": params["s"]},
                                user_attrs={RETRY_OF_ATTR: trial.number}, skip_if_exists=False)
        log(f"trial {trial.number} was abandoned ({reason}): marked failed, parameters queued again")
        recovered.append(trial.number)
    return recovered


def used_budget(study: optuna.Study) -> int:
    """Trials that count against n_trials: complete, running, or failed without being queued again."""
    count = 0
    for trial in study.get_trials(deepcopy=False):
        if trial.state in (TrialState.COMPLETE, TrialState.PRUNED, TrialState.RUNNING):
            count += 1
        elif trial.state == TrialState.FAIL and not trial.user_attrs.get(REQUEUED_ATTR):
            count += 1
    return count


class _Heartbeat:
    """Writes the trial's heartbeat attribute every `interval` seconds while the trial runs."""

    def __init__(self, trial: optuna.Trial, interval: float) -> None:
        self._trial = trial
        self._interval = interval
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sweep-heartbeat", daemon=True)

    def __enter__(self) -> "_Heartbeat":
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self._interval):
            try:
                self._trial.set_user_attr(HEARTBEAT_ATTR, time.time())
            except (UpdateFinishedTrialError, RuntimeError):
                return

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def run_trials(
    config: StudyConfig,
    study: optuna.Study,
    storage: BaseStorage,
    evaluator: EpisodeEvaluator,
    *,
    n_trials: int | None = None,
    records_dir: Path | None = None,
    progress: bool = True,
    after_trial: Callable[[optuna.Study], None] | None = None,
) -> int:
    """Run trials until the study holds `n_trials` (default config.n_trials); return how many ran here."""
    from tqdm import tqdm

    budget = n_trials if n_trials is not None else config.n_trials
    me = WorkerIdentity.current()
    episodes = config.episodes()
    # The bar only where a terminal shows it; logs get one line per trial with the study's count.
    show_bar = progress and sys.stderr.isatty()
    bar = tqdm(total=budget, desc=f"sweep {config.study_name}", unit="trial", file=sys.stderr,
               disable=not show_bar, dynamic_ncols=True)
    log = bar.write if show_bar else (lambda text: print(text, file=sys.stderr, flush=True))
    ran_here = 0
    try:
        while True:
            recover_stale_trials(study, storage, config.stale_after_s, me, log)
            used = used_budget(study)
            bar.n = min(used, budget)
            bar.refresh()
            if used >= budget:
                break
            trial = study.ask()
            trial.set_user_attr(WORKER_ATTR, me.encode())
            trial.set_user_attr(HEARTBEAT_ATTR, time.time())
            rho = trial.suggest_float("rho", config.rho.low, config.rho.high, log=config.rho.log)
            s = trial.suggest_int("s", config.s.low, config.s.high, step=config.s.step, log=config.s.log)
            start = time.perf_counter()
            try:
                with _Heartbeat(trial, config.heartbeat_s):
                    records = evaluator(rho, s, run_id=f"{config.study_name}/trial-{trial.number}")
                check_records(records, episodes)
            except KeyboardInterrupt:
                # Not the point's fault: queue it again so the resumed sweep evaluates it.
                trial.set_user_attr(REQUEUED_ATTR, True)
                trial.set_user_attr(ERROR_ATTR, "interrupted")
                study.tell(trial, state=TrialState.FAIL)
                study.enqueue_trial({"rho": rho, "s": s}, user_attrs={RETRY_OF_ATTR: trial.number})
                raise
            except GritsError as exc:
                trial.set_user_attr(ERROR_ATTR, str(exc))
                study.tell(trial, state=TrialState.FAIL)
                raise
            except Exception as exc:  # a crash in one trial must not end the study
                trial.set_user_attr(ERROR_ATTR, f"{type(exc).__name__}: {exc}")
                study.tell(trial, state=TrialState.FAIL)
                log(f"trial {trial.number} (rho={rho:.3g}, s={s}) failed: {type(exc).__name__}: {exc}")
                ran_here += 1
                continue
            metrics = summarize_records(records)
            values = objective_values(metrics, config.objective)
            if records_dir is not None:
                save_parquet_atomic(trial_records_path(records_dir, trial.number), records)
            try:
                for key, value in metrics.as_attrs().items():
                    trial.set_user_attr(key, value)
                for key, value in guidance_attrs(records).items():
                    trial.set_user_attr(key, value)
                trial.set_user_attr("duration_s", time.perf_counter() - start)
                study.tell(trial, values)
            except (UpdateFinishedTrialError, ValueError):
                log(f"trial {trial.number} was declared abandoned by another worker; its result is dropped")
                continue
            ran_here += 1
            log(f"trial {trial.number} [{min(used_budget(study), budget)}/{budget}]: rho={rho:.3g} s={s} success={metrics.success_rate:.2f} "
                f"spillage={metrics.spillage_rate:.2f} -> {', '.join(f'{v:.3f}' for v in values)} "
                f"({metrics.n_episodes} episodes, {time.perf_counter() - start:.1f} s)")
            if after_trial is not None:
                after_trial(study)
    finally:
        bar.close()
    return ran_here
