"""A sweep's `reference` methods run once on the validation episodes, and every trial is paired with them."""

from __future__ import annotations

import json
import math

import pandas as pd
import pytest
import yaml

from grits_lab.errors import ConfigError
from grits_lab.tune import reference as reference_module
from grits_lab.tune.job import run_sweep
from grits_lab.tune.reference import paired_counts, reference_path
from grits_lab.tune.study_config import load_study_config
from tests.evaluation.conftest import models  # noqa: F401  (session fixture: tiny trained checkpoints)
from tests.tune.test_sweep_pool import grits_sweep


def _records(rows):
    """Records of four episodes: (task_success, spillage, scoop_failure, error) per episode."""
    return pd.DataFrame([{"food": "soybeans", "level": "low", "trial": i, "seed": 100 + i, "task_success": ts,
                          "spillage": sp, "scoop_failure": sf, "error": err}
                         for i, (ts, sp, sf, err) in enumerate(rows)])


def test_paired_counts_count_each_outcome_episode_by_episode_with_the_sign_test():
    reference = _records([(False, True, False, ""), (False, True, False, ""), (True, False, False, ""), (False, True, False, "")])
    trial = _records([(True, False, False, ""), (True, False, False, ""), (True, False, False, ""), (False, False, False, "crash")])
    row = paired_counts(reference, trial)
    assert row["paired"] == 4
    assert (row["task_success_reference"], row["task_success_trial"]) == (1, 3)
    assert (row["task_success_only_reference"], row["task_success_only_trial"]) == (0, 2)
    assert row["task_success_p"] == pytest.approx(0.5)  # 2 of 2 discordant one way: 2 * (1/4)
    assert (row["spillage_reference"], row["spillage_trial"], row["spillage_only_reference"]) == (3, 0, 3)
    assert row["spillage_p"] == pytest.approx(0.25)
    # the errored episode is a scoop failure and no success, as the sweep scores it
    assert (row["scoop_failure_reference"], row["scoop_failure_trial"], row["scoop_failure_only_trial"]) == (0, 1, 1)


def test_episodes_pair_by_their_seed_not_by_their_row_order():
    reference = _records([(True, False, False, ""), (False, True, False, "")])
    trial = _records([(True, False, False, ""), (False, True, False, "")]).iloc[::-1]
    row = paired_counts(reference, trial)
    assert row["task_success_only_reference"] == row["task_success_only_trial"] == 0
    other = trial.assign(seed=trial["seed"] + 1)  # other seeds: nothing pairs
    assert paired_counts(reference, other)["paired"] == 0


def test_the_reference_runs_once_before_the_trials_and_each_trial_is_paired_with_it(sweep_file, monkeypatch):
    config = load_study_config(sweep_file(reference=["dp"], n_trials=3, objective={"mode": "multi"}))
    runs = []
    real = reference_module.run_references

    def counted(config, evaluator, records_dir, log=None):
        ran = real(config, evaluator, records_dir, log=lambda text: None)
        runs.append(ran)
        return ran

    monkeypatch.setattr(reference_module, "run_references", counted)
    summary = run_sweep(config, progress=False, plots=False)
    records_dir = config.study_dir / "records"
    reference = pd.read_parquet(reference_path(records_dir, "dp"))
    assert runs == [["dp"]]
    assert set(reference["method"]) == {"dp"} and reference["rho"].isna().all()
    assert sorted(reference["seed"]) == sorted(e.seed for e in config.episodes())

    # every completed trial is paired with it, with the counts its records give
    table = pd.read_csv(config.study_dir / "reference.csv")
    assert sorted(table["trial"]) == [0, 1, 2] and (table["paired"] == len(config.episodes())).all()
    for _, row in table.iterrows():
        trial = pd.read_parquet(records_dir / f"trial_{row['trial']:05d}.parquet")
        assert row["task_success_trial"] == int(trial["task_success"].sum())
        assert row["spillage_reference"] == int(reference["spillage"].sum())
        both = trial.merge(reference, on=["food", "level", "trial", "seed"], suffixes=("", "_ref"))
        assert row["spillage_only_reference"] == int((both["spillage_ref"] & ~both["spillage"]).sum())
    block = summary["reference"]["dp"]
    assert block["best"]["trial"] == summary["best"]["trial"]
    assert block["n_episodes"] == len(config.episodes())
    assert block["spillage_rate"] == pytest.approx(reference["spillage"].mean())
    assert {r["trial"] for r in block["front"]} == {t["trial"] for t in summary["pareto_front"]}
    # the study itself carries the reference's rates, so that a reader of the storage (optuna-dashboard) shows them
    import optuna

    from grits_lab.tune.storage import open_storage
    storage, _ = open_storage(config.storage, config.study_dir / "journal.log")
    carried = optuna.load_study(study_name=config.study_name, storage=storage).user_attrs["reference:dp"]
    assert carried["spillage_rate"] == pytest.approx(reference["spillage"].mean())
    assert carried["success_rate"] == pytest.approx(reference["task_success"].mean())
    assert carried["n_episodes"] == len(config.episodes())
    best_yaml = (config.study_dir / "best.yaml").read_text()
    assert f"against dp on {len(config.episodes())} paired episodes" in best_yaml
    assert yaml.safe_load(best_yaml)["guidance"]["rho"] == pytest.approx(summary["best"]["rho"])

    # resumed with a larger budget: the stored reference is kept, not run again
    summary = run_sweep(config, n_trials=4, progress=False, plots=False)
    assert runs == [["dp"], []] and summary["states"] == {"COMPLETE": 4}
    assert json.loads((config.study_dir / "summary.json").read_text())["reference"]["dp"]["n_episodes"] == len(config.episodes())


def test_a_reference_added_to_a_running_study_keeps_its_trials_and_report_only_runs_nothing(sweep_file):
    plain = load_study_config(sweep_file(n_trials=2))
    run_sweep(plain, progress=False, plots=False)
    with_reference = load_study_config(sweep_file(n_trials=2, reference=["dp"]))
    assert with_reference.identity() == plain.identity()
    summary = run_sweep(with_reference, report_only=True, plots=False)
    assert summary["reference"] == {} and any("reference dp: no stored records yet" in n for n in summary["notes"])
    assert not reference_path(with_reference.study_dir / "records", "dp").exists()
    summary = run_sweep(with_reference, progress=False, plots=False)
    assert summary["states"] == {"COMPLETE": 2}  # no trial ran again
    assert summary["reference"]["dp"]["n_episodes"] == len(with_reference.episodes())


def test_a_stored_reference_of_other_episodes_is_run_again(sweep_file):
    config = load_study_config(sweep_file(n_trials=1, reference=["dp"]))
    run_sweep(config, progress=False, plots=False)
    path = reference_path(config.study_dir / "records", "dp")
    pd.read_parquet(path).iloc[:-1].to_parquet(path)  # one episode short
    run_sweep(config, progress=False, plots=False)
    assert len(pd.read_parquet(path)) == len(config.episodes())


def test_a_damaged_reference_is_run_again_and_a_damaged_trial_record_is_left_out_of_the_pairing(sweep_file):
    config = load_study_config(sweep_file(n_trials=2, reference=["dp"]))
    run_sweep(config, progress=False, plots=False)
    records_dir = config.study_dir / "records"
    path = reference_path(records_dir, "dp")
    path.write_text("not parquet")
    (records_dir / "trial_00001.parquet").write_text("not parquet either")
    summary = run_sweep(config, report_only=True, plots=False)
    assert summary["reference"] == {} and any("dp" in n and "not readable" in n for n in summary["notes"])
    assert not (config.study_dir / "reference.csv").exists()  # no pairing now: none left from before
    summary = run_sweep(config, progress=False, plots=False)  # runs the reference again
    assert len(pd.read_parquet(path)) == len(config.episodes())
    assert sorted(pd.read_csv(config.study_dir / "reference.csv")["trial"]) == [0]  # trial 1's records are unreadable
    assert summary["reference"]["dp"]["best"] is None or summary["reference"]["dp"]["best"]["trial"] == summary["best"]["trial"]


def test_a_reference_that_raises_is_logged_in_one_line_and_the_trials_go_on(sweep_file, capsys, monkeypatch):
    from grits_lab.tune.synthetic import SyntheticEvaluator

    config = load_study_config(sweep_file(n_trials=2, reference=["dp"]))

    def broken(self, method, run_id):
        raise RuntimeError("simulator crashed")

    monkeypatch.setattr(SyntheticEvaluator, "reference", broken)
    summary = run_sweep(config, progress=False, plots=False)
    assert summary["states"] == {"COMPLETE": 2} and summary["reference"] == {}
    lines = [line for line in capsys.readouterr().err.splitlines() if "reference dp failed" in line]
    assert len(lines) == 1 and "RuntimeError: simulator crashed" in lines[0]
    assert not reference_path(config.study_dir / "records", "dp").exists()


@pytest.mark.parametrize("overrides, key", [
    ({"reference": ["dp", "dp"]}, "reference"),
    ({"reference": ["../x"]}, "reference[0]"),
    ({"reference": ["dp", "a/b"]}, "reference[1]"),
    ({"reference": [""]}, "reference[0]"),
    ({"reference": ["dp "]}, "reference[0]"),
])
def test_a_bad_reference_fails_on_load_naming_the_key(sweep_file, overrides, key):
    with pytest.raises(ConfigError) as info:
        load_study_config(sweep_file(**overrides))
    assert f"`{key}`" in str(info.value) and "\n" not in str(info.value)


def test_the_tuned_method_or_an_unknown_one_is_refused_as_reference_before_any_study_exists(sweep_file, models, tmp_path):  # noqa: F811
    config, _ = grits_sweep(sweep_file, models, tmp_path, {"backend": "serial"})
    data = yaml.safe_load((tmp_path / f"{config.study_name}.yaml").read_text())
    path = tmp_path / "ref.yaml"
    path.write_text(yaml.safe_dump({**data, "reference": ["grits"]}))
    with pytest.raises(ConfigError, match="`reference`.*tuned method `grits`"):
        load_study_config(path)
    path.write_text(yaml.safe_dump({**data, "reference": ["dp_plus"]}))
    with pytest.raises(ConfigError, match="`reference`: dp_plus is no method"):
        run_sweep(load_study_config(path), progress=False, plots=False)
    assert not config.study_dir.exists()


def test_a_grits_sweep_runs_unguided_dp_on_its_validation_episodes(sweep_file, models, tmp_path):  # noqa: F811
    config, _ = grits_sweep(sweep_file, models, tmp_path, {"backend": "serial"}, n_trials=1)
    data = yaml.safe_load((tmp_path / f"{config.study_name}.yaml").read_text())
    path = tmp_path / "ref.yaml"
    path.write_text(yaml.safe_dump({**data, "reference": ["dp"]}))
    config = load_study_config(path)
    summary = run_sweep(config, progress=False, plots=False)
    records_dir = config.study_dir / "records"
    reference = pd.read_parquet(reference_path(records_dir, "dp"))
    trial = pd.read_parquet(records_dir / "trial_00000.parquet")
    assert list(reference["method"].unique()) == ["dp"] and (reference["error"] == "").all()
    assert reference["rho"].isna().all() and (reference["s"] == -1).all()  # no guidance
    assert sorted(reference["seed"]) == sorted(trial["seed"])
    assert reference["checkpoint_policy"].tolist() == trial["checkpoint_policy"].tolist()
    assert summary["reference"]["dp"]["n_episodes"] == 2 and not math.isnan(summary["reference"]["dp"]["success_rate"])


def test_the_report_of_a_sweep_pairs_its_front_with_the_reference(sweep_file, tmp_path):
    from grits_lab.report import build_report

    config = load_study_config(sweep_file(reference=["dp"], n_trials=4, objective={"mode": "multi"}))
    summary = run_sweep(config, progress=False, plots=False)
    build_report(config.study_dir, tmp_path / "report")
    markdown = (tmp_path / "report" / "report.md").read_text()
    section = markdown.split("### Sweep: the success-spillage front against the reference, episode by episode", 1)[1].split("###", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| Diffusion Policy")]
    assert len(rows) == len(summary["pareto_front"])
    every = markdown.split("### Sweep: every paired trial, by rho, against the reference, episode by episode", 1)[1].split("###", 1)[0]
    assert len([line for line in every.splitlines() if line.startswith("| Diffusion Policy")]) == 4
    for row, paired in zip(rows, sorted(summary["reference"]["dp"]["front"], key=lambda r: r["trial"])):
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert int(cells[1]) == paired["trial"] and int(cells[4]) == paired["paired"]
        assert cells[5].startswith(f"{paired['task_success_reference']} → {paired['task_success_trial']} "
                                   f"(−{paired['task_success_only_reference']} +{paired['task_success_only_trial']},")


def test_a_sweeps_summary_page_renders_its_front_against_the_reference(sweep_file, tmp_path):
    from grits_lab.report import load_run
    from grits_lab.report.results_pages import render_page
    from grits_lab.report.summary import write_summary

    config = load_study_config(sweep_file(reference=["dp"], n_trials=3, objective={"mode": "multi"}))
    summary = run_sweep(config, progress=False, plots=False)
    page = tmp_path / "site" / "studies" / "s" / "summaries" / "sweep"
    write_summary(load_run(config.study_dir), page, "grits-lab report STUDY --summary-to PAGE")
    assert (page / "reference.csv").read_text() == (config.study_dir / "reference.csv").read_text()
    text = render_page("<!-- generated: sweep_reference sweep -->\n<!-- end generated -->\n", page / "README.md", tmp_path / "site")
    rows = [line for line in text.splitlines() if line.startswith("| Diffusion Policy")]
    assert len(rows) == len(summary["pareto_front"]) and "File: [reference.csv](reference.csv)" in text
    every = render_page("<!-- generated: sweep_trials sweep -->\n<!-- end generated -->\n", page / "README.md", tmp_path / "site")
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in every.splitlines() if line.startswith("| Diffusion Policy")]
    stored = pd.read_csv(page / "reference.csv")
    assert len(rows) == len(stored) == 3  # every completed trial, not only the front
    assert [float(r[2]) for r in rows] == sorted(float(r[2]) for r in rows)  # by rho
    front = set(stored.loc[stored["pareto_front"], "trial"])
    assert {int(r[1]) for r in rows if r[4] == "yes"} == front and all(r[4] == "" for r in rows if int(r[1]) not in front)
    # a later summary of the same folder without a reference leaves no reference.csv behind
    (config.study_dir / "reference.csv").unlink()
    write_summary(load_run(config.study_dir), page, "again")
    assert not (page / "reference.csv").exists()


def test_a_sweeps_summary_page_dates_the_sweep_by_its_first_trial_and_names_what_it_did_not_record(sweep_file, tmp_path):
    from grits_lab.report import load_run
    from grits_lab.report.results_pages import render_page
    from grits_lab.report.summary import write_summary

    config = load_study_config(sweep_file(n_trials=2))
    run_sweep(config, progress=False, plots=False)
    page = tmp_path / "site" / "studies" / "s" / "summaries" / "sweep"
    write_summary(load_run(config.study_dir), page, "grits-lab report STUDY --summary-to PAGE")
    first = pd.to_datetime(pd.read_csv(config.study_dir / "trials.csv")["datetime_start"]).min()
    provenance = json.loads((page / "provenance.json").read_text())
    assert provenance["run started (UTC)"] == first.strftime("%Y-%m-%d %H:%M:%S")
    text = render_page("<!-- generated: provenance sweep -->\n<!-- end generated -->\n", page / "README.md", tmp_path / "site")
    assert "records' code: not recorded." in text and "host not recorded" in text
    assert f"run started {first.strftime('%Y-%m-%d %H:%M:%S')} UTC." in text and "None" not in text


def _stored_reference(front_flags, rhos):
    rows = []
    for trial, (flag, rho) in enumerate(zip(front_flags, rhos)):
        row = {"reference": "dp", "trial": trial, "rho": rho, "s": 30, "pareto_front": flag, "paired": 4}
        for outcome in ("task_success", "spillage", "scoop_failure"):
            row |= {f"{outcome}_reference": 2, f"{outcome}_trial": 1, f"{outcome}_only_reference": 1,
                    f"{outcome}_only_trial": 0, f"{outcome}_p": 1.0}
        rows.append(row)
    return pd.DataFrame(rows)


@pytest.mark.parametrize("flags", [[True, False, True], ["True", "False", " true"], [1, 0, 1], [1.0, 0.0, 1.0], ["yes", "no", "1"]])
def test_the_front_flag_reads_as_pandas_a_csv_or_a_hand_edit_writes_it(flags):
    from grits_lab.report.sweep import sweep_reference_table

    table = sweep_reference_table(_stored_reference(flags, [2.5, 0.1, 10.0]), every_trial=True)
    assert table.display["Front"].tolist() == ["", "yes", "yes"]  # by rho: 0.1, 2.5, 10
    assert sweep_reference_table(_stored_reference(flags, [2.5, 0.1, 10.0])).display["Trial"].tolist() == ["0", "2"]


def test_trials_sort_by_rho_as_a_number_even_when_the_file_holds_text():
    from grits_lab.report.sweep import sweep_reference_table

    table = sweep_reference_table(_stored_reference([False] * 3, ["10", "2.5", "0.3"]), every_trial=True)
    assert table.display["Trial"].tolist() == ["2", "1", "0"]


def test_a_page_says_when_no_trial_on_the_front_is_paired(tmp_path):
    from grits_lab.report.results_pages import render_page

    page = tmp_path / "studies" / "s" / "summaries" / "sweep"
    page.mkdir(parents=True)
    _stored_reference([False, False], [0.1, 1.0]).to_csv(page / "reference.csv", index=False)
    text = render_page("<!-- generated: sweep_reference sweep -->\n<!-- end generated -->\n", page / "README.md", tmp_path)
    assert "No trial on the front is paired in reference.csv." in text and "|" not in text
    every = render_page("<!-- generated: sweep_trials sweep -->\n<!-- end generated -->\n", page / "README.md", tmp_path)
    assert len([line for line in every.splitlines() if line.startswith("| Diffusion Policy")]) == 2


def test_a_sweep_is_dated_by_its_first_trial_in_utc_whatever_the_offsets():
    from grits_lab.report.summary import _sweep_started

    trials = pd.DataFrame({"datetime_start": ["2026-12-05 13:08:00.5+00:00", "2026-12-05 13:00:00", "2026-12-05 14:00:00+02:00",
                                              "not a time", None]})
    assert _sweep_started(trials) == "2026-12-05 12:00:00"
    assert _sweep_started(pd.DataFrame({"datetime_start": [None]})) is None and _sweep_started(None) is None
