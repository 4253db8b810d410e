"""The study loop in one process: defaults first, seeded reproducibility, resumption, crashes, stale trials."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import time

import pandas as pd
import pytest
import yaml
from optuna.trial import TrialState

from grits_lab.errors import InputError
from grits_lab.tune.study_config import load_study_config
from grits_lab.tune.objective import check_records, make_evaluator
from grits_lab.tune.outputs import write_outputs
from grits_lab.tune.storage import open_storage
from grits_lab.tune.study import (
    HEARTBEAT_ATTR, REQUEUED_ATTR, RETRY_OF_ATTR, WORKER_ATTR, WorkerIdentity, open_study,
    recover_stale_trials, run_trials, stale_reason,
)
from grits_lab.tune.synthetic import episode_probabilities
from tests.tune.sweep_helpers import REPO


def run_study(config, journal, n_trials=None):
    storage, _ = open_storage(str(journal), journal)
    study = open_study(config, storage)
    run_trials(config, study, storage, make_evaluator(config), n_trials=n_trials, progress=False)
    return study, storage


def history(study):
    return [(t.number, t.state.name, t.params.get("rho"), t.params.get("s"), t.values)
            for t in study.get_trials(deepcopy=False)]


def test_paper_defaults_run_first_and_budget_is_respected(sweep_file, tmp_path):
    config = load_study_config(sweep_file(n_trials=4))
    study, _ = run_study(config, tmp_path / "j.log")
    trials = study.get_trials(deepcopy=False)
    assert [t.state for t in trials] == [TrialState.COMPLETE] * 4
    assert (trials[0].params["rho"], trials[0].params["s"]) == (2.5, 30)
    assert trials[0].user_attrs["enqueued"] is True
    assert all(t.user_attrs["n_episodes"] == 8 for t in trials)
    # Opening the study again queues the defaults no second time.
    study, _ = run_study(config, tmp_path / "j.log")
    assert sum((t.params["rho"], t.params["s"]) == (2.5, 30) for t in study.get_trials()) == 1


def test_same_seed_same_study_and_other_seed_other_study(sweep_file, tmp_path):
    config = load_study_config(sweep_file(n_trials=6))
    a, _ = run_study(config, tmp_path / "a.log")
    b, _ = run_study(config, tmp_path / "b.log")
    assert history(a) == history(b)
    other = dataclasses.replace(config, sampler=dataclasses.replace(config.sampler, seed=4))
    c, _ = run_study(other, tmp_path / "c.log")
    assert history(c)[0] == history(a)[0]  # the enqueued defaults
    assert history(c)[1:] != history(a)[1:]


def test_stopped_and_resumed_study_equals_an_uninterrupted_one(sweep_file, tmp_path):
    config = load_study_config(sweep_file(n_trials=7))
    resumed, _ = run_study(config, tmp_path / "r.log", n_trials=3)
    before = history(resumed)
    resumed, _ = run_study(config, tmp_path / "r.log")
    straight, _ = run_study(config, tmp_path / "s.log")
    assert history(resumed)[:3] == before
    assert history(resumed) == history(straight)


def test_crashing_trials_are_kept_as_failed_and_the_study_goes_on(sweep_file, tmp_path):
    config = load_study_config(sweep_file(n_trials=8, synthetic={"crash_above_rho": 2.0}))
    study, _ = run_study(config, tmp_path / "j.log")
    trials = study.get_trials(deepcopy=False)
    failed = [t for t in trials if t.state == TrialState.FAIL]
    assert failed, "with rho in [0.5, 8] and a crash above 2, some trial must crash"
    assert all("configured crash" in t.user_attrs["error"] and t.params["rho"] > 2.0 for t in failed)
    assert all(t.params["rho"] <= 2.0 for t in trials if t.state == TrialState.COMPLETE)
    assert len(trials) == 8  # failed trials count against the budget: a crashing region cannot loop forever


def _dead_pid() -> int:
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def test_stale_running_trial_is_failed_and_its_parameters_rerun(sweep_file, tmp_path):
    config = load_study_config(sweep_file(n_trials=3))
    journal = tmp_path / "j.log"
    storage, _ = open_storage(str(journal), journal)
    study = open_study(config, storage)
    # A worker that died mid-trial: it took the enqueued defaults and never reported back.
    orphan = study.ask()
    orphan.suggest_float("rho", 0.5, 8.0, log=True)
    orphan.suggest_int("s", 0, 90, step=6)
    dead = WorkerIdentity(WorkerIdentity.current().host, _dead_pid(), "deadbeef")
    orphan.set_user_attr(WORKER_ATTR, dead.encode())
    orphan.set_user_attr(HEARTBEAT_ATTR, time.time())
    run_trials(config, study, storage, make_evaluator(config), progress=False)
    trials = study.get_trials(deepcopy=False)
    assert trials[0].state == TrialState.FAIL and trials[0].user_attrs[REQUEUED_ATTR] is True
    assert "gone" in trials[0].user_attrs["error"]
    retry = [t for t in trials if t.user_attrs.get(RETRY_OF_ATTR) == 0]
    assert len(retry) == 1 and retry[0].state == TrialState.COMPLETE
    assert (retry[0].params["rho"], retry[0].params["s"]) == (2.5, 30)
    assert sum(t.state == TrialState.COMPLETE for t in trials) == 3  # the stale trial did not use budget
    # A second recovery pass finds nothing more to do.
    assert recover_stale_trials(study, storage, config.stale_after_s, WorkerIdentity.current(), log=lambda s: None) == []


def test_heartbeat_decides_for_workers_on_other_hosts(sweep_file, tmp_path):
    config = load_study_config(sweep_file())
    storage, _ = open_storage(str(tmp_path / "j.log"), tmp_path / "j.log")
    study = open_study(config, storage)
    trial = study.ask()
    trial.set_user_attr(WORKER_ATTR, WorkerIdentity("elsewhere", os.getpid(), "abcd").encode())
    now = time.time()
    trial.set_user_attr(HEARTBEAT_ATTR, now - 10)
    frozen = study.get_trials(deepcopy=False)[0]
    me = WorkerIdentity.current()
    assert stale_reason(frozen, me, stale_after_s=60, now=now) is None
    assert "no heartbeat" in stale_reason(frozen, me, stale_after_s=60, now=now + 100)


def test_outputs_best_yaml_is_a_guidance_override(sweep_file, tmp_path):
    config = load_study_config(sweep_file(n_trials=5, objective={"mode": "multi"}))
    study, _ = run_study(config, tmp_path / "j.log")
    summary = write_outputs(study, config, tmp_path / "out", "j.log", "synthetic")
    best = yaml.safe_load((tmp_path / "out" / "best.yaml").read_text())
    assert set(best) == {"guidance"} and set(best["guidance"]) == {"rho", "s"}
    assert isinstance(best["guidance"]["s"], int)
    table = pd.read_parquet(tmp_path / "out" / "trials.parquet")
    assert list(table["number"]) == list(range(5))
    assert pd.read_csv(tmp_path / "out" / "trials.csv")["success_rate"].tolist() == pytest.approx(table["success_rate"].tolist())
    assert (tmp_path / "out" / "pareto.png").stat().st_size > 0
    assert (tmp_path / "out" / "importance.png").stat().st_size > 0
    assert summary["defaults"]["trial"] == 0 and summary["best"]["n_episodes"] == 8


def test_the_best_of_two_front_trials_with_equal_scores_is_the_earlier_one(sweep_file):
    import optuna

    from grits_lab.tune.outputs import best_trial

    config = load_study_config(sweep_file(objective={"mode": "multi"}))
    study = optuna.create_study(directions=["maximize", "minimize"])
    for success, spill in ((0.70, 0.30), (0.65, 0.25)):  # 0.4 and 0.39999999999999997 in floats: one score
        study.add_trial(optuna.trial.create_trial(
            params={"rho": 0.1, "s": 30}, distributions={"rho": optuna.distributions.FloatDistribution(0.05, 8.0, log=True),
                                                          "s": optuna.distributions.IntDistribution(0, 90, step=6)},
            values=[success, spill], user_attrs={"success_rate": success, "spillage_rate": spill}))
    best, note = best_trial(study, config)
    assert best.number == 0 and "Pareto front" in note


def test_trials_tied_on_outcomes_go_to_the_one_whose_guidance_lowered_p_spill_most(sweep_file):
    import optuna

    from grits_lab.tune.outputs import best_trial

    config = load_study_config(sweep_file(objective={"mode": "multi"}))
    study = optuna.create_study(directions=["maximize", "minimize"])
    distributions = {"rho": optuna.distributions.FloatDistribution(0.05, 30.0, log=True),
                     "s": optuna.distributions.IntDistribution(0, 90, step=6)}
    for rho, change in ((2.5, -0.01), (12.0, -0.15), (0.3, None)):  # all three: success 1.0, spillage 0.0
        attrs = {"success_rate": 1.0, "spillage_rate": 0.0, **({"p_spill_change": change} if change is not None else {})}
        study.add_trial(optuna.trial.create_trial(params={"rho": rho, "s": 30}, distributions=distributions,
                                                  values=[1.0, 0.0], user_attrs=attrs))
    study.add_trial(optuna.trial.create_trial(params={"rho": 20.0, "s": 30}, distributions=distributions, values=[0.75, 0.0],
                                              user_attrs={"success_rate": 0.75, "spillage_rate": 0.0, "p_spill_change": -0.4}))
    best, note = best_trial(study, config)
    assert best.number == 1 and "larger drop in median P(spill)" in note  # outcomes first: trial 3 failed a scoop


def test_a_trials_guidance_effect_is_the_median_over_every_compared_plan():
    import numpy as np
    import pandas as pd

    from grits_lab.tune.study import guidance_attrs

    records = pd.DataFrame({"plan_p_spill_unguided": [np.array([0.5, 0.4]), np.array([0.6])],
                            "plan_p_spill_guided": [np.array([0.4, 0.3]), np.array([0.5])],
                            "plan_displacement_mm": [np.array([1.0, 3.0]), np.array([2.0])]})
    attrs = guidance_attrs(records)
    assert np.isclose(attrs["p_spill_change"], (0.4 - 0.5) / 0.5) and attrs["displacement_mm"] == 2.0
    assert guidance_attrs(pd.DataFrame({"task_success": [True]})) == {}  # unguided records carry no plans


def test_override_files_carry_the_sweeps_evaluation_overrides_with_the_trials_rho_and_s(sweep_file, tmp_path):
    from grits_lab.evaluation.evaluation_config import load_evaluation_config

    overrides = {"guidance": {"step": "normalized"}, "transfer": {"max_joint_step": 0.3}}
    config = load_study_config(sweep_file(n_trials=4, objective={"mode": "multi"}, evaluation={"overrides": overrides}))
    study, _ = run_study(config, tmp_path / "j.log")
    out = tmp_path / "out"
    write_outputs(study, config, out, "j.log", "synthetic", plots=False)
    trials = pd.read_parquet(out / "trials.parquet").set_index("number")
    files = [out / "best.yaml", *sorted((out / "front").glob("trial_*.yaml"))]
    assert len(files) >= 2
    for path in files:
        override = yaml.safe_load(path.read_text())
        rho, s = override["guidance"]["rho"], override["guidance"]["s"]
        assert override == {"guidance": {"step": "normalized", "rho": rho, "s": s}, "transfer": {"max_joint_step": 0.3}}
        assert (((trials["rho"] - rho).abs() < 1e-12) & (trials["s"] == s)).any()  # one trial's own rho and s
        protocol = load_evaluation_config(REPO / "experiments" / "evaluate_cpu.yaml", override)
        assert (protocol.guidance.step, protocol.guidance.rho, protocol.guidance.s) == ("normalized", rho, s)
        assert protocol.trials == 5 and protocol.seed == 0  # the protocol's episodes, not the sweep's


def test_outputs_hold_one_override_per_pareto_front_trial(sweep_file, tmp_path):
    config = load_study_config(sweep_file(n_trials=8, objective={"mode": "multi"}))
    study, _ = run_study(config, tmp_path / "j.log")
    out = tmp_path / "out"
    (out / "front").mkdir(parents=True)
    (out / "front" / "trial_99999.yaml").write_text("guidance: {rho: 1.0, s: 30}\n")  # a trial no longer on the front
    summary = write_outputs(study, config, out, "j.log", "synthetic", plots=False)
    table = pd.read_parquet(out / "trials.parquet")
    done = table[table["state"] == "COMPLETE"]

    def dominated(row):
        better = (done["success_rate"] >= row.success_rate) & (done["spillage_rate"] <= row.spillage_rate)
        strictly = (done["success_rate"] > row.success_rate) | (done["spillage_rate"] < row.spillage_rate)
        return bool((better & strictly).any())

    expected = sorted(int(row.number) for row in done.itertuples() if not dominated(row))
    assert expected and len(expected) < len(done)  # the synthetic trade-off leaves some trials dominated
    assert sorted(table.loc[table["pareto_front"], "number"]) == expected
    assert sorted(p.name for p in (out / "front").iterdir()) == [f"trial_{n:05d}.yaml" for n in expected]
    for n in expected:
        override = yaml.safe_load((out / "front" / f"trial_{n:05d}.yaml").read_text())
        row = table.set_index("number").loc[n]
        assert override == {"guidance": {"rho": pytest.approx(row.rho), "s": int(row.s)}}
    assert [t["trial"] for t in summary["pareto_front"]] == expected


def test_importance_with_one_trial_is_skipped_with_a_note(sweep_file, tmp_path):
    config = load_study_config(sweep_file(n_trials=1))
    study, _ = run_study(config, tmp_path / "j.log")
    summary = write_outputs(study, config, tmp_path / "out", "j.log", "synthetic")
    assert not (tmp_path / "out" / "importance.png").exists()
    assert any("at least 2 completed trials" in note for note in summary["notes"])
    assert (tmp_path / "out" / "best.yaml").exists()


def test_records_must_cover_exactly_the_validation_episodes(sweep_file):
    config = load_study_config(sweep_file())
    evaluator = make_evaluator(config)
    records = evaluator(2.5, 30, run_id="x")
    check_records(records, config.episodes())
    with pytest.raises(InputError, match="differ from the validation set"):
        check_records(records.iloc[1:], config.episodes())
    shifted = records.assign(seed=records["seed"] + 1)
    with pytest.raises(InputError, match="differ from the validation set"):
        check_records(shifted, config.episodes())


def test_synthetic_stand_in_is_deterministic_and_guidance_trades_spillage_for_failures(sweep_file):
    config = load_study_config(sweep_file())
    evaluator = make_evaluator(config)
    pd.testing.assert_frame_equal(evaluator(1.0, 30, "a").drop(columns="wall_time_s"),
                                  evaluator(1.0, 30, "a").drop(columns="wall_time_s"))
    spill = [episode_probabilities(rho, 30, "soybeans", "high", 100)[0] for rho in (0.0, 1.0, 2.5, 8.0)]
    fail = [episode_probabilities(rho, 30, "soybeans", "high", 100)[1] for rho in (0.0, 1.0, 2.5, 8.0)]
    assert spill == sorted(spill, reverse=True) and fail == sorted(fail)
    assert (evaluator(1.0, 30, "a")["method"] == "synthetic").all()


def test_defaults_and_identity_missing_after_the_creator_died_are_written_by_the_next_worker(
        sweep_file, tmp_path, monkeypatch):
    import optuna

    from grits_lab.tune import study as study_module

    monkeypatch.setattr(study_module, "CREATOR_GRACE_S", 0.2)
    config = load_study_config(sweep_file(n_trials=3))
    journal = tmp_path / "j.log"
    storage, _ = open_storage(str(journal), journal)
    # What a creator killed right after creating the study leaves: no defaults, no identity.
    storage.create_new_study([optuna.study.StudyDirection.MAXIMIZE], config.study_name)
    study, _ = run_study(config, journal)
    first = study.get_trials(deepcopy=False)[0]
    assert (first.params["rho"], first.params["s"]) == (2.5, 30) and first.user_attrs["enqueued"] is True
    assert study.user_attrs[study_module.IDENTITY_ATTR] == config.identity()
    # Idempotent: later workers queue them no second time, and the identity is now checked.
    study, _ = run_study(config, journal, n_trials=4)
    assert sum((t.params["rho"], t.params["s"]) == (2.5, 30) for t in study.get_trials()) == 1
    other = load_study_config(sweep_file(n_trials=3, rho={"high": 9.0}))
    with pytest.raises(Exception, match="different search space"):
        open_study(other, open_storage(str(journal), journal)[0])
