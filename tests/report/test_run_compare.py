"""`grits-lab compare-runs`: two runs on the same seeds, paired episode by episode."""

from __future__ import annotations

import pandas as pd
import pytest

from grits_lab.cli import main
from grits_lab.errors import InputError
from grits_lab.intervals import sign_test_p
from grits_lab.report.run_compare import compare_runs, comparison_markdown, paired_episodes, with_paired_outcomes
from grits_lab.report.run_records import normalize_records
from grits_lab.sim.spill_metrics import attribution_columns
from tests.report.synthetic_records import episode


def _run(outcomes: list[tuple], tmp_path, name: str) -> pd.DataFrame:
    """dp episodes on sago/low, trials 0.., each (outcome, scoop_steps, particles lost in the carry[,
    particles in the target bowl])."""
    rows = []
    for trial, (outcome, steps, carry, *transferred) in enumerate(outcomes):
        row = episode("dp", "sago", "low", trial, outcome)
        row.update({c: 0 for c in attribution_columns()}, scoop_steps=steps, spilled_carry_off_spoon=carry)
        if transferred:
            row["transferred"] = transferred[0]
        rows.append(row)
    frame = pd.DataFrame(rows)
    (tmp_path / name).mkdir()
    frame.to_parquet(tmp_path / name / "episodes.parquet")
    return frame


def test_the_sign_test_is_the_exact_binomial_tail():
    assert sign_test_p(0, 0) == 1.0
    assert sign_test_p(0, 5) == pytest.approx(2 / 32)  # 5 of 5 one way
    assert sign_test_p(1, 4) == pytest.approx(2 * 6 / 32)  # at most 1 of 5 either way
    assert sign_test_p(3, 3) == 1.0


def test_paired_episodes_count_equal_scoops_and_outcomes_changed_either_way(tmp_path, capsys):
    before = _run([("success", 40, 0), ("transfer_fail", 40, 2), ("transfer_fail", 40, 1), ("spill", 40, 0)], tmp_path, "before")
    after = _run([("success", 40, 0), ("success", 40, 0), ("transfer_fail", 40, 1), ("spill", 41, 0)], tmp_path, "after")
    table = compare_runs(with_paired_outcomes(normalize_records(before)), with_paired_outcomes(normalize_records(after)))
    row = table.set_index("method").loc["dp"]
    assert row["paired"] == 4 and row["scoop_equal"] == 3  # trial 3's scoop took one action more
    assert (row["task_success_before"], row["task_success_after"]) == (1, 2)
    assert (row["task_success_only_before"], row["task_success_only_after"]) == (0, 1)
    assert (row["spill_after_scoop_before"], row["spill_after_scoop_after"], row["spill_after_scoop_only_before"]) == (2, 1, 1)
    assert main(["compare-runs", str(tmp_path / "before"), str(tmp_path / "after"), "--output-dir", str(tmp_path / "cmp")]) == 0
    out = capsys.readouterr().out
    assert "| Diffusion Policy | 4 | 3/4 | 1 → 2 (−0 +1, p 1) |" in out
    assert (tmp_path / "cmp" / "comparison.csv").is_file() and (tmp_path / "cmp" / "comparison.md").is_file()


def test_lifted_food_delivered_needs_nine_tenths_in_the_target_bowl_and_no_spill_after_the_scoop(tmp_path):
    # 20 lifted each (synthetic_records): 18 delivered is 90 %, 17 is not; a carry loss fails it; nothing lifted fails it.
    before = _run([("success", 40, 0, 18), ("success", 40, 0, 17), ("success", 40, 1, 20), ("scoop_fail", 40, 0, 0)], tmp_path, "b")
    after = _run([("success", 40, 0, 18), ("success", 40, 0, 18), ("success", 40, 0, 20), ("scoop_fail", 40, 0, 0)], tmp_path, "a")
    before = with_paired_outcomes(normalize_records(before))
    assert before["lifted_food_delivered"].tolist() == [True, False, False, False]
    table = compare_runs(before, with_paired_outcomes(normalize_records(after)))
    row = table.set_index("method").loc["dp"]
    assert (row["lifted_food_delivered_before"], row["lifted_food_delivered_after"]) == (1, 3)
    assert (row["lifted_food_delivered_only_before"], row["lifted_food_delivered_only_after"]) == (0, 2)
    # A comparison written before the outcome existed still renders, without its column.
    old = table.drop(columns=[c for c in table.columns if c.startswith("lifted_food_delivered")]).assign(before="b", after="a")
    assert "lifted food delivered" not in comparison_markdown(old)
    assert "lifted food delivered" in comparison_markdown(table.assign(before="b", after="a"))


def test_runs_on_other_seeds_are_refused(tmp_path, capsys):
    _run([("success", 40, 0)], tmp_path, "before")
    other = _run([("success", 40, 0)], tmp_path, "other").assign(seed=12345)
    other.to_parquet(tmp_path / "other" / "episodes.parquet")
    assert main(["compare-runs", str(tmp_path / "before"), str(tmp_path / "other")]) != 0
    assert "different seeds" in capsys.readouterr().err
    twice = pd.read_parquet(tmp_path / "before" / "episodes.parquet")
    (tmp_path / "twice").mkdir()
    pd.concat([twice, twice.assign(rho=1.0, s=10)]).to_parquet(tmp_path / "twice" / "episodes.parquet")
    assert main(["compare-runs", str(tmp_path / "before"), str(tmp_path / "twice")]) != 0
    assert "2 records share their episode" in capsys.readouterr().err
    before = normalize_records(pd.read_parquet(tmp_path / "before" / "episodes.parquet"))
    with pytest.raises(InputError, match="share no episode"):
        paired_episodes(before, before.assign(food="orange"))


def test_an_experiment_page_renders_the_comparison_written_into_its_folder(tmp_path):
    from grits_lab.report.results_pages import render_all

    _run([("success", 40, 0), ("transfer_fail", 40, 2)], tmp_path, "v1")
    _run([("success", 40, 0), ("success", 40, 0)], tmp_path, "v2")
    folder = tmp_path / "studies" / "s" / "summaries" / "v2"
    assert main(["compare-runs", str(tmp_path / "v1"), str(tmp_path / "v2"), "--output-dir", str(folder)]) == 0
    (folder / "README.md").write_text("# v2\n\n<!-- generated: comparison v2 -->\n<!-- end generated -->\n")
    page = render_all(tmp_path)[folder / "README.md"]
    assert "| Diffusion Policy | 2 | 2/2 | 1 → 2 (−0 +1, p 1) |" in page
    assert "v1 → v2, on the same seeds" in page and "[comparison.csv](comparison.csv)" in page


def test_every_method_is_paired_with_dp_on_the_episodes_both_ran(tmp_path):
    from grits_lab.report.build import build_report
    from grits_lab.report.results_pages import render_all
    from grits_lab.report.run_compare import compare_methods
    from grits_lab.report.run_records import load_run
    from grits_lab.report.summary import write_summary

    rows = []
    for method, outcomes in (("dp", ["spill", "spill", "success", "success"]),
                             ("grits", ["success", "spill", "success", "scoop_fail", "success"])):
        for trial, outcome in enumerate(outcomes):  # grits's trial 4 has no dp episode to pair with
            row = episode(method, "sago", "low", trial, outcome)
            row.update({c: 0 for c in attribution_columns()}, scoop_steps=40)
            rows.append(row)
    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame(rows).to_parquet(run / "episodes.parquet")
    table = compare_methods(load_run(run).episodes)
    row = table.set_index("method").loc["grits"]
    assert row["reference"] == "dp" and row["paired"] == 4
    assert (row["spillage_before"], row["spillage_after"], row["spillage_only_before"], row["spillage_only_after"]) == (2, 1, 1, 0)
    assert (row["scoop_failure_only_before"], row["scoop_failure_only_after"]) == (0, 1)
    assert (row["task_success_before"], row["task_success_after"]) == (2, 2)
    assert (row["task_success_only_before"], row["task_success_only_after"]) == (1, 1)
    assert "dp" not in set(table["method"])
    # Without the reference there is nothing to pair.
    assert compare_methods(load_run(run).episodes.query("method != 'dp'")).empty

    build_report(run, tmp_path / "report")
    text = (tmp_path / "report" / "report.md").read_text()
    assert "## Paired with Diffusion Policy" in text and "| 2 → 1 (−1 +0, p 1) " in text
    folder = tmp_path / "studies" / "s" / "summaries" / "pair"
    write_summary(load_run(run), folder, "grits-lab report run --summary-to studies/s/summaries/pair")
    assert (folder / "paired.csv").is_file()
    (folder / "README.md").write_text("# Pair\n\n<!-- generated: paired pair -->\n<!-- end generated -->\n")
    page = render_all(tmp_path)[folder / "README.md"]
    assert "| GRITS | 4 | 2 → 2 (−1 +1, p 1) | 2 → 1 (−1 +0, p 1) |" in page


def test_a_method_at_two_guidance_settings_is_paired_with_dp_once_per_setting_and_with_each_other(tmp_path):
    from grits_lab.report.build import build_report
    from grits_lab.report.results_pages import render_all
    from grits_lab.report.run_compare import compare_methods
    from grits_lab.report.run_records import load_run
    from grits_lab.report.summary import write_summary

    rows = []
    for method, rho, s, outcomes in (("dp", float("nan"), -1, ["spill", "spill", "success"]),
                                     ("grits", 0.07, 78, ["success", "spill", "success"]),
                                     ("grits", 2.5, 30, ["scoop_fail", "scoop_fail", "spill"])):
        for trial, outcome in enumerate(outcomes):
            row = episode(method, "sago", "low", trial, outcome, rho=rho, s=s)
            row.update({c: 0 for c in attribution_columns()}, scoop_steps=40)
            rows.append(row)
    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame(rows).to_parquet(run / "episodes.parquet")
    table = compare_methods(load_run(run).episodes)
    with_dp = table[table["reference"] == "dp"].set_index("method_name")
    assert sorted(with_dp.index) == ["GRITS (rho=0.07, s=78)", "GRITS (rho=2.5, s=30)"]
    tuned, paper = with_dp.loc["GRITS (rho=0.07, s=78)"], with_dp.loc["GRITS (rho=2.5, s=30)"]
    assert (tuned["paired"], tuned["spillage_before"], tuned["spillage_after"], tuned["spillage_only_before"]) == (3, 2, 1, 1)
    assert (paper["scoop_failure_before"], paper["scoop_failure_after"], paper["task_success_after"]) == (0, 2, 0)
    # The tuned setting against the paper's values on the same seeds, whatever order the records come in:
    # success 0 -> 2, scoop failure 2 -> 0.
    between = table[table["reference"] != "dp"]
    assert len(between) == 1
    row = between.iloc[0]
    assert (row["reference_name"], row["method_name"], row["paired"]) == ("GRITS (rho=2.5, s=30)", "GRITS (rho=0.07, s=78)", 3)
    assert (row["task_success_before"], row["task_success_after"], row["task_success_only_after"]) == (0, 2, 2)
    assert (row["scoop_failure_before"], row["scoop_failure_after"], row["spillage_before"], row["spillage_after"]) == (2, 0, 1, 1)
    reversed_records = load_run(run).episodes.iloc[::-1].reset_index(drop=True)
    again = compare_methods(reversed_records)
    assert again[again["reference"] != "dp"].iloc[0]["reference_name"] == "GRITS (rho=2.5, s=30)"
    folder = tmp_path / "studies" / "s" / "summaries" / "pair"
    write_summary(load_run(run), folder, "grits-lab report run --summary-to studies/s/summaries/pair")
    (folder / "README.md").write_text("# Pair\n\n<!-- generated: paired pair -->\n<!-- end generated -->\n")
    page = render_all(tmp_path)[folder / "README.md"]
    assert "| GRITS (rho=0.07, s=78) | Diffusion Policy | 3 | 1 → 2 (−0 +1, p 1) | 2 → 1 (−1 +0, p 1) |" in page
    assert "| GRITS (rho=2.5, s=30) | Diffusion Policy | 3 |" in page
    assert "| GRITS (rho=0.07, s=78) | GRITS (rho=2.5, s=30) | 3 | 0 → 2 (−0 +2, p 0.5) |" in page
    assert "its setting at the paper's values (rho 2.5, s 30)" in page
    build_report(run, tmp_path / "report")
    assert "## Paired with each other" in (tmp_path / "report" / "report.md").read_text()


def test_spills_before_the_pour_count_the_scoop_lift_and_carry_and_not_the_pour(tmp_path):
    from grits_lab.report.run_compare import compare_methods, paired_methods_markdown
    from grits_lab.report.run_records import load_run
    from grits_lab.report.summary import summary_table

    lost = [{}, {"spilled_scoop_over_rim": 1}, {"spilled_lift_off_spoon": 2}, {"spilled_carry_off_spoon": 1},
            {"spilled_pour_poured_outside": 3}, {"spilled_after_pour_bounced_out": 1}]
    rows = []
    for method in ("dp", "grits"):
        for trial, spilled in enumerate(lost if method == "dp" else [{}] * len(lost)):
            row = episode(method, "sago", "low", trial, "success")
            row.update({c: 0 for c in attribution_columns()}, scoop_steps=40, **spilled)
            rows.append(row)
    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame(rows).to_parquet(run / "episodes.parquet")
    frame = with_paired_outcomes(load_run(run).episodes)
    dp = frame[frame["method"] == "dp"]
    assert dp["spill_before_pour"].tolist() == [False, True, True, True, False, False]
    assert dp["spill_after_scoop"].tolist() == [False, False, True, True, True, True]
    summary = summary_table(load_run(run).episodes).set_index(["method", "outcome"])
    assert (summary.loc[("dp", "spill_before_pour"), "k"], summary.loc[("dp", "spill_before_pour"), "n"]) == (3, 6)
    assert summary.loc[("grits", "spill_before_pour"), "k"] == 0
    table = compare_methods(load_run(run).episodes)
    row = table.set_index("method").loc["grits"]
    assert (row["spill_before_pour_before"], row["spill_before_pour_after"], row["spill_before_pour_only_before"]) == (3, 0, 3)
    head, cells, _ = paired_methods_markdown(table)
    assert cells[0][head.index("spill before the pour")] == "3 → 0 (−3 +0, p 0.25)"
    # A paired table written before the outcome existed still renders, without its column.
    old = table.drop(columns=[c for c in table.columns if c.startswith("spill_before_pour")])
    assert "spill before the pour" not in paired_methods_markdown(old)[0]


def test_an_output_dir_that_cannot_be_written_is_refused_in_one_line_before_the_comparison(tmp_path, capsys):
    _run([("success", 40, 0)], tmp_path, "before")
    _run([("spill", 40, 0)], tmp_path, "after")
    (tmp_path / "a_file").write_text("")
    assert main(["compare-runs", str(tmp_path / "before"), str(tmp_path / "after"), "--output-dir", str(tmp_path / "a_file" / "cmp")]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and f"cannot write {tmp_path / 'a_file' / 'cmp'}: {tmp_path / 'a_file'} is not a directory" in err[0], err
    assert "Diffusion Policy" not in captured.out  # refused before the comparison was made


def test_runs_whose_guidance_settings_differ_are_paired_by_episode_and_the_caption_says_so(tmp_path, capsys):
    for name, (rho, s) in {"before": (2.5, 30), "after": (1.0, 24)}.items():
        frame = _run([("success", 40, 0), ("spill", 40, 0)], tmp_path, name)
        frame["method"], frame["rho"], frame["s"] = "grits", rho, s
        frame.to_parquet(tmp_path / name / "episodes.parquet")
    assert main(["compare-runs", str(tmp_path / "before"), str(tmp_path / "after")]) == 0
    out = capsys.readouterr().out
    assert "GRITS ran at rho 2.5, s 30 in before and at rho 1, s 24 in after: the changes include what that setting did." in out
