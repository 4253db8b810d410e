"""Report layer: known table values and Wilson intervals from fixed records, missing data shown as
missing, a self-contained HTML page, booktabs LaTeX, sweep Pareto front, and CLI bad input."""

from __future__ import annotations

import base64
import json
import math
import re

import pandas as pd
import pytest

from grits_lab.cli import main
from grits_lab.errors import InputError
from grits_lab.report import build_report, load_run, normalize_records, wilson_interval
from grits_lab.report.sweep import summarize_sweep
from grits_lab.report.tables import claims_table, failure_stages, failure_table, method_table, per_food_table
from grits_lab.report.vocabulary import MAIN_METHODS, MISSING
from tests.report.synthetic_records import episode, plausible_run


def fixed_records() -> pd.DataFrame:
    """GRITS: 8 successes, 1 spill, 1 scoop failure on sago. DP: 6 successes, 3 spills, 1 error
    (recorded as a success, so the error rule must turn it into a failure), no fudge for DP."""
    rows = []
    grits = ["success"] * 8 + ["spill", "scoop_fail"]
    dp = ["success"] * 7 + ["spill"] * 3
    for i, outcome in enumerate(grits):
        # The scoop failure spilled first: Fig. 6 must count it as a spillage failure.
        early = True if outcome == "scoop_fail" else None
        rows.append(episode("grits", "sago", "low" if i < 5 else "high", i % 5, outcome, spilled_before_scoop=early))
    for i, outcome in enumerate(dp):
        rows.append(episode("dp", "sago", "low" if i < 5 else "high", i % 5, outcome, error="sim crashed" if i == 0 else ""))
    for i in range(4):
        rows.append(episode("grits", "fudge", "low", i, "success" if i < 3 else "transfer_fail"))
    return pd.DataFrame(rows)


@pytest.fixture(scope="module")
def records() -> pd.DataFrame:
    return normalize_records(fixed_records())


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    run = tmp_path_factory.mktemp("run")
    frame = plausible_run(0, skip={"dp": ["fudge"]})
    half = len(frame) // 2
    frame.iloc[:half].to_parquet(run / "part-000.parquet", index=False)
    frame.iloc[half:].to_parquet(run / "part-001.parquet", index=False)
    frame.to_parquet(run / "episodes.parquet", index=False)  # consolidated copy beside its shards
    (run / "config.yaml").write_text("root_seed: 0\ntrials_per_level: 5\n")
    (run / "provenance.json").write_text('{"git_commit": "feedbeef"}')
    return run, frame, build_report(run)


def test_wilson_interval_matches_hand_computed_values():
    # p = 0.8, n = 10, z = 1.96: centre (0.8 + z^2/20) / (1 + z^2/10) = 0.7167, half-width 0.2266.
    assert wilson_interval(8, 10) == pytest.approx((0.4902, 0.9433), abs=1e-4)
    assert wilson_interval(1, 10) == pytest.approx((0.0179, 0.4042), abs=1e-4)
    assert wilson_interval(0, 10) == (0.0, pytest.approx(0.2775, abs=1e-4))
    assert wilson_interval(10, 10) == (pytest.approx(0.7225, abs=1e-4), 1.0)
    assert all(math.isnan(v) for v in wilson_interval(0, 0))


def test_fig5_table_has_known_counts_rates_and_intervals(records):
    table = method_table(records, MAIN_METHODS, "fig5", "t", "c")
    data = table.data.set_index("method")
    grits = data.loc["grits"]
    assert (grits["episodes"], grits["task_success_k"], grits["spillage_k"], grits["scoop_failure_k"]) == (14, 11, 1, 1)
    assert grits["task_success_rate"] == pytest.approx(11 / 14)
    assert (grits["task_success_ci_low"], grits["task_success_ci_high"]) == pytest.approx(wilson_interval(11, 14))
    assert grits["spillage_paper"] == 0.04 and grits["task_success_paper"] == 0.82
    dp = data.loc["dp"]
    # The errored episode was recorded as a success: it must count as a failure and be shown as an error.
    assert (dp["episodes"], dp["task_success_k"], dp["errors"]) == (10, 6, 1)
    shown = table.display.set_index("Method")
    assert shown.loc["GRITS", "Task success (simulation)"] == "78.6% [52.4, 92.4] (11/14)"
    assert shown.loc["GRITS", "Task success (real robot (paper))"] == "82.0%"
    assert shown.loc["Diffusion Policy", "Task success (real robot (paper))"] == MISSING


def test_missing_method_is_reported_missing_not_zero(records):
    table = method_table(records, MAIN_METHODS, "fig5", "t", "c")
    bc = table.data.set_index("method").loc["bc"]
    assert bc["missing"] and math.isnan(bc["task_success_rate"]) and math.isnan(bc["task_success_k"])
    row = table.display.set_index("Method").loc["Behavior cloning"]
    assert row["Task success (simulation)"] == MISSING and row["Episodes"] == MISSING
    assert "0.0%" not in " ".join(row.astype(str))
    assert any("Behavior cloning" in n and "SCONE" in n and n.startswith("Missing") for n in table.notes)


def test_fig6_counts_spillage_before_scoop_and_marks_missing_food(records):
    table = per_food_table(records)
    data = table.data
    grits_sago = data[(data["method"] == "grits") & (data["food"] == "sago")].set_index("category")["k"]
    # 8 successes; the spill and the early-spilling scoop failure are both spillage failures.
    assert grits_sago.to_dict() == {"success": 8, "spillage": 2, "scoop_failure": 0, "other_failure": 0, "error": 0}
    dp_sago = data[(data["method"] == "dp") & (data["food"] == "sago")].set_index("category")["k"]
    assert (dp_sago["success"], dp_sago["spillage"], dp_sago["error"]) == (6, 3, 1)
    dp_fudge = data[(data["method"] == "dp") & (data["food"] == "fudge")]
    assert dp_fudge["k"].isna().all() and (dp_fudge["episodes"] == 0).all()
    shown = table.display.set_index("Food")
    assert shown.loc["FD fudge", "Diffusion Policy: Success"] == MISSING
    assert shown.loc["FD fudge", "GRITS: Success"] == "3"
    assert any("Diffusion Policy: " in n and "FD fudge" in n for n in table.notes)


def test_claims_compare_spillage_reduction_with_the_paper(records):
    claims = claims_table(records).data.set_index("quantity")
    reduction = claims.loc["Spillage reduction, GRITS relative to Diffusion Policy"]
    assert reduction["simulation"] == pytest.approx(1 - (1 / 14) / (3 / 10))
    # 1/14 against 3/10: a reduction beyond the paper's 40 %, on intervals that overlap: no verdict
    assert reduction["note"] == "undecided at n = 10 and 14: Wilson intervals overlap"
    assert claims.loc["Diffusion Policy (Post.): spillage", "note"] == "no simulated episodes"


def test_a_spillage_reduction_gets_a_verdict_only_when_the_wilson_intervals_are_apart():
    def claim(grits_spills: int, dp_spills: int) -> str:
        rows = [episode(m, "sago", "low" if i < 20 else "high", i % 20, "spill" if i < spills else "success")
                for m, spills in (("grits", grits_spills), ("dp", dp_spills)) for i in range(40)]
        claims = claims_table(normalize_records(pd.DataFrame(rows))).data.set_index("quantity")
        return claims.loc["Spillage reduction, GRITS relative to Diffusion Policy", "note"]

    # 1/40 [0.4 %, 12.9 %] against 20/40 [35.2 %, 64.8 %]: apart
    assert claim(1, 20) == "holds, Wilson intervals apart"
    # 5/40 [5.5 %, 26.1 %] against 10/40 [14.2 %, 40.2 %]: a 50 % reduction whose intervals overlap
    assert claim(5, 10) == "undecided at n = 40: Wilson intervals overlap"
    # 8/40 against 10/40: 20 %, short of the paper's 40 %, and overlapping: still no verdict
    assert claim(8, 10) == "undecided at n = 40: Wilson intervals overlap"
    # 1 of 4 against 1 of 4, the first screen of a small run: nothing decided
    assert claim_at(1, 1, 4) == "undecided at n = 4: Wilson intervals overlap"
    # 20/40 against 1/40: GRITS spilled more, apart
    assert claim(20, 1) == "does not hold: GRITS spilled more, Wilson intervals apart"
    # 22/40 [39.8 %, 69.3 %] against 40/40 [91.2 %, 100 %]: apart, a 45 % reduction (the paper's is > 40 %)
    assert claim(22, 40) == "holds, Wilson intervals apart"
    # 30/40 [59.8 %, 85.8 %] against 40/40: apart, but a 25 % reduction
    assert claim(30, 40) == "GRITS spilled less, Wilson intervals apart, by less than the paper's reduction"


def claim_at(grits_spills: int, dp_spills: int, n: int) -> str:
    rows = [episode(m, "sago", "low", i, "spill" if i < spills else "success")
            for m, spills in (("grits", grits_spills), ("dp", dp_spills)) for i in range(n)]
    claims = claims_table(normalize_records(pd.DataFrame(rows))).data.set_index("quantity")
    return claims.loc["Spillage reduction, GRITS relative to Diffusion Policy", "note"]


def test_failure_table_counts_each_episode_once_at_the_stage_that_ended_it():
    # One DP episode per stage, in the task's order, with the particle counts the simulation records.
    rows = [
        episode("dp", "sago", "low", 0, "success"),
        episode("dp", "sago", "low", 1, "success", error="worker lost"),
        episode("dp", "sago", "low", 2, "spill"),
        episode("dp", "sago", "low", 3, "spill_and_scoop_fail"),  # spilled during the scoop: counted there
        episode("dp", "sago", "low", 4, "scoop_fail"),
        episode("dp", "sago", "high", 0, "transfer_fail"),  # clean scoop, 3 grains lost on the way
        episode("dp", "sago", "high", 1, "transfer_fail"),  # clean scoop, nothing spilled, nothing delivered
    ]
    frame = pd.DataFrame(rows)
    frame["spilled_transfer"] = 0
    frame.loc[5, "spilled_transfer"] = 3
    frame["transfer_ik_failures"] = [0, 0, 0, 0, 0, 0, 9]
    frame["transfer_max_joint_step_rad"] = [0.2, 0.2, 0.2, math.nan, math.nan, 0.2, 1.4]  # no transfer after a failed scoop
    data = failure_table(normalize_records(frame)).data.iloc[0]
    assert data["episodes"] == 7
    assert {k: data[f"{k}_k"] for k in ("task_success", "error", "scoop_spill", "scoop_failure", "transfer_spill", "not_delivered")} == {
        "task_success": 1, "error": 1, "scoop_spill": 2, "scoop_failure": 1, "transfer_spill": 1, "not_delivered": 1}
    assert (data["transfer_unreachable_k"], data["transfers"]) == (1, 4)  # the errored episode's transfer is not counted
    assert data["posture_flip_k"] == 1  # the 1.4 rad step
    assert math.isnan(data["reach_check_failed_k"])  # records without the reach check


def test_failure_table_counts_transfers_whose_reach_check_failed():
    rows = [episode("dp", "sago", "low", t, "success") for t in range(3)] + [episode("dp", "sago", "low", 3, "scoop_fail")]
    frame = pd.DataFrame(rows)
    frame["spilled_transfer"] = 0
    frame["transfer_ik_failures"] = [1, 0, 2, 0]
    frame["transfer_max_joint_step_rad"] = [0.2, 0.2, 0.6, math.nan]
    frame["transfer_reachable"] = [True, True, False, None]  # no transfer after the failed scoop
    data = failure_table(normalize_records(frame)).data.iloc[0]
    assert (data["reach_check_failed_k"], data["reach_checked"]) == (1, 3)
    assert (data["posture_flip_k"], data["transfers"]) == (1, 3)


def test_failure_stages_partition_records_whose_flags_disagree():
    # A record source that marks an episode both a success and a spill: counted once, as the spill.
    frame = pd.DataFrame([episode("dp", "sago", "low", 0, "spill"), episode("dp", "sago", "low", 1, "success")])
    frame.loc[0, "task_success"] = True
    frame["spilled_transfer"] = 0
    masks = failure_stages(normalize_records(frame))
    counted = sum(masks[key].astype(int) for key in ("task_success", "error", "scoop_spill", "scoop_failure",
                                                      "transfer_spill", "not_delivered"))
    assert counted.tolist() == [1, 1] and masks["scoop_spill"].tolist() == [True, False]


def test_failure_table_without_particle_totals_counts_the_failures_after_the_scoop_together(records):
    table = failure_table(records)
    assert (table.data["episodes"] == table.data[["task_success_k", "error_k", "scoop_spill_k", "scoop_failure_k",
                                                  "after_scoop_k"]].sum(axis=1)).all()
    assert table.data["transfer_spill_k"].isna().all()
    assert table.display["Transfers with an unreachable pose"].eq(MISSING).all()
    assert table.display["Reach check failed"].eq(MISSING).all()
    assert "lack `spilled_transfer`" in table.notes[0]


def test_flag_missing_outside_an_errored_episode_is_rejected():
    frame = fixed_records()
    frame["spillage"] = frame["spillage"].astype(object)
    frame.loc[3, "spillage"] = None
    with pytest.raises(InputError, match="`spillage` is missing in 1"):
        normalize_records(frame)


def test_shards_and_consolidated_file_are_counted_once(built):
    run, frame, _ = built
    loaded = load_run(run, exclude=run / "report")
    assert len(loaded.episodes) == len(frame)
    assert loaded.duplicates_dropped == len(frame)


def test_report_writes_every_format_and_a_self_contained_html(built):
    run, _, result = built
    out = result.out_dir
    assert out == run / "report"
    for name in ("report.md", "report.html", "report.tex", "provenance.json", "csv/fig5_overall.csv",
                 "csv/fig6_per_food.csv", "csv/fig8_ablation.csv", "csv/breakdown_long.csv",
                 "figures/fig5_overall.png", "figures/fig6_per_food.png", "figures/fig8_ablation.png"):
        assert (out / name).is_file(), name
    page = (out / "report.html").read_text()
    sources = re.findall(r'\bsrc="([^"]*)"', page)
    assert len(sources) == len(list((out / "figures").glob("*.png")))
    for src in sources:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    assert all(h.startswith("#") for h in re.findall(r'\bhref="([^"]*)"', page))
    assert "<link" not in page and "<script" not in page and "url(" not in page
    for text in ("real robot (paper)", "simulation", "feedbeef", "root_seed: 0", "report code git commit",
                 "same episode seeds for every method", "FD fudge"):
        assert text in page, text


def test_latex_uses_booktabs_and_escapes(built):
    tex = (built[2].out_dir / "latex" / "fig5_overall.tex").read_text()
    assert "\\toprule" in tex and "\\midrule" in tex and "\\bottomrule" in tex
    assert "\\%" in tex and "82.0\\%" in tex


def test_sweep_pareto_front_and_best_parameters():
    trials = pd.DataFrame({
        "number": [0, 1, 2, 3, 4],
        "state": ["COMPLETE", "COMPLETE", "COMPLETE", "FAIL", "COMPLETE"],
        "rho": [2.5, 1.0, 4.0, 8.0, 0.5],
        "s": [30, 30, 60, 90, 12],
        "success_rate": [0.8, 0.7, 0.9, math.nan, 0.6],
        "spillage_rate": [0.05, 0.02, 0.10, math.nan, 0.05],
    })
    summary = summarize_sweep(trials, None)
    assert summary.objectives == {"success_rate": "maximize", "spillage_rate": "minimize"}
    assert sorted(summary.trials.loc[summary.trials["pareto"], "number"]) == [0, 1, 2]  # 4 is dominated by 0


def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["report", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "run directory not found" in err
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "other.parquet").write_bytes(pd.DataFrame({"x": [1]}).to_parquet())
    assert main(["report", str(tmp_path / "empty")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no episode records" in err and "other.parquet" in err


def test_cli_on_a_full_disk_is_one_line_and_exit_2(built, tmp_path, full_disk, capsys):
    run, _, _ = built
    assert main(["report", str(run), "--output-dir", str(tmp_path / "report")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no space left on device" in err[0]


def test_runs_given_together_report_a_method_once_per_guidance_setting(tmp_path, capsys):
    protocol, tuned, out = tmp_path / "protocol", tmp_path / "tuned", tmp_path / "out"
    protocol.mkdir()
    tuned.mkdir()
    rows = [episode("dp", "sago", "low", t, "success" if t < 3 else "spill", run_id="protocol") for t in range(4)]
    rows += [episode("grits", "sago", "low", t, "success" if t < 1 else "spill", run_id="protocol") for t in range(4)]
    pd.DataFrame(rows).to_parquet(protocol / "episodes.parquet", index=False)
    pd.DataFrame([episode("grits", "sago", "low", t, "success", rho=1.26, s=60, run_id="tuned")
                  for t in range(4)]).to_parquet(tuned / "episodes.parquet", index=False)
    assert main(["report", str(protocol), str(tuned), "--output-dir", str(out)]) == 0
    fig5 = pd.read_csv(out / "csv" / "fig5_overall.csv").set_index("variant")
    assert fig5.loc["dp", "task_success_k"] == 3
    assert fig5.loc["grits[rho=2.5, s=30]", "task_success_k"] == 1
    assert fig5.loc["grits[rho=1.26, s=60]", "task_success_k"] == 4
    assert (fig5.loc[["dp", "grits[rho=2.5, s=30]", "grits[rho=1.26, s=60]"], "episodes"] == 4).all()
    assert str(tuned) in (out / "report.md").read_text()
    # Labels are short unless two settings need more digits to be told apart.
    close = normalize_records(pd.DataFrame([episode("grits", "sago", "low", 0, "success", rho=r, s=30) for r in (1.26053, 1.26112, 0.955106)]))
    assert sorted(set(close["variant_name"])) == ["GRITS (rho=0.95511, s=30)", "GRITS (rho=1.2605, s=30)", "GRITS (rho=1.2611, s=30)"]
    # A second run without records, or one that is not there, is one line before any work.
    (tmp_path / "empty").mkdir()
    for other, message in ((tmp_path / "empty", "no episode records"), (tmp_path / "nope", "run directory not found")):
        assert main(["report", str(protocol), str(other), "--output-dir", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and message in err and str(other) in err
    assert main(["report", str(protocol), str(tuned), "--video-episodes", "1"]) == 2
    assert "one run directory" in capsys.readouterr().err


def test_methods_reports_only_the_named_methods_and_refuses_one_the_records_lack(tmp_path, capsys):
    # a run directory whose dp_post was stopped after one episode: `--methods` leaves it out of every table
    run, out, summary = tmp_path / "run", tmp_path / "out", tmp_path / "summary"
    run.mkdir()
    rows = [episode("dp", "sago", "low", t, "success" if t < 3 else "spill") for t in range(4)]
    rows += [episode("grits", "sago", "low", t, "success") for t in range(4)] + [episode("dp_post", "sago", "low", 0, "spill")]
    pd.DataFrame(rows).to_parquet(run / "episodes.parquet", index=False)
    assert main(["report", str(run), "--methods", "dp", "grits", "--output-dir", str(out), "--summary-to", str(summary)]) == 0
    fig5 = pd.read_csv(out / "csv" / "fig5_overall.csv").set_index("variant")
    assert fig5.loc["dp", "task_success_k"] == 3 and fig5.loc["grits", "episodes"] == 4
    assert fig5["episodes"].fillna(0).get("dp_post", 0) == 0  # listed as missing, no episode counted
    assert "dp_post" not in set(pd.read_csv(summary / "summary.csv")["method"])
    provenance = json.loads((summary / "provenance.json").read_text())
    assert sorted(provenance["methods"]) == ["dp", "grits"] and "--methods dp grits" in provenance["command"]
    capsys.readouterr()
    assert main(["report", str(run), "--methods", "dp", "grits_horizon", "--output-dir", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "grits_horizon" in err and "dp, dp_post, grits" in err
    assert not (tmp_path / "x").exists()  # refused before anything is written


def test_runs_guided_by_different_predictors_report_one_variant_per_predictor(tmp_path):
    old, new, out = tmp_path / "old", tmp_path / "new", tmp_path / "out"
    for folder, digest, outcomes in ((old, "e541c70af52bc554", ["spill"] * 3 + ["success"]), (new, "43d4a5a96cef9c8d", ["success"] * 3 + ["spill"])):
        folder.mkdir()
        rows = [{**episode("grits", "sago", "low", t, o, run_id="evaluate"), "checkpoint_predictor": digest} for t, o in enumerate(outcomes)]
        # the raw-cloud ablation records its predictor under its own checkpoint key
        rows += [{**episode("grits_raw", "sago", "low", t, o, run_id="evaluate"), "checkpoint_predictor_raw": digest[::-1]}
                 for t, o in enumerate(outcomes)]
        if folder == old:
            rows += [{**episode("dp", "sago", "low", t, "success", run_id="evaluate"), "checkpoint_predictor": None} for t in range(4)]
        pd.DataFrame(rows).to_parquet(folder / "episodes.parquet", index=False)
    assert main(["report", str(old), str(new), "--output-dir", str(out)]) == 0
    fig5 = pd.read_csv(out / "csv" / "fig5_overall.csv").set_index("variant")
    assert fig5.loc["grits[predictor e541c70a]", "spillage_k"] == 3
    assert fig5.loc["grits[predictor 43d4a5a9]", "spillage_k"] == 1
    assert fig5.loc["dp", "episodes"] == 4
    fig8 = pd.read_csv(out / "csv" / "fig8_ablation.csv").set_index("variant")
    assert fig8.loc[f"grits_raw[predictor {'e541c70af52bc554'[::-1][:8]}]", "spillage_k"] == 3
    # the same predictor in both runs is the same episode twice: refused as before
    pd.DataFrame([{**episode("grits", "sago", "low", 0, "success", run_id="evaluate"), "checkpoint_predictor": "43d4a5a96cef9c8d"}]
                 ).to_parquet(old / "episodes.parquet", index=False)
    assert main(["report", str(old), str(new), "--output-dir", str(tmp_path / "out2")]) == 2


def test_records_of_two_protocols_are_labelled_with_their_protocol_and_never_pooled(tmp_path):
    before, now, out = tmp_path / "before", tmp_path / "now", tmp_path / "out"
    for folder in (before, now):
        folder.mkdir()
    # The same episodes (the same run_id and seeds) under two protocols: a before/after comparison.
    pd.DataFrame([episode("dp", "sago", "low", t, "success" if t < 1 else "spill", run_id="evaluate", protocol="scoop-v3")
                  for t in range(4)]).to_parquet(before / "episodes.parquet", index=False)
    pd.DataFrame([episode("dp", "sago", "low", t, "success", run_id="evaluate", protocol="scoop-v4") for t in range(4)]
                 + [episode("grits", "sago", "low", t, "success", run_id="evaluate", protocol="scoop-v4") for t in range(4)]
                 ).to_parquet(now / "episodes.parquet", index=False)
    assert main(["report", str(before), str(now), "--output-dir", str(out)]) == 0
    fig5 = pd.read_csv(out / "csv" / "fig5_overall.csv").set_index("variant")
    assert fig5.loc["dp[scoop-v3]", "task_success_k"] == 1 and fig5.loc["dp[scoop-v3]", "episodes"] == 4
    assert fig5.loc["dp[scoop-v4]", "task_success_k"] == 4 and fig5.loc["dp[scoop-v4]", "episodes"] == 4
    assert fig5.loc["grits[scoop-v4]", "method_name"] == "GRITS (scoop-v4)"  # every method names its protocol
    assert "scoop-v3 (4 episodes), scoop-v4 (8 episodes)" in (out / "report.md").read_text()
    # One protocol: no label; records written before the column existed are read as docs/protocol.md says.
    one = normalize_records(pd.DataFrame([episode("dp", "sago", "low", 0, "success")]))
    assert list(one["variant"]) == ["dp"]
    unrecorded = pd.DataFrame([episode("dp", "sago", "low", 0, "success")]).drop(columns="protocol")
    assert list(normalize_records(unrecorded)["protocol"]) == ["unversioned (before scoop-v4)"]
    assert list(normalize_records(unrecorded.assign(spilled_scoop_over_rim=0))["protocol"]) == ["scoop-v4"]


def test_runs_that_cannot_be_reported_together_are_refused_in_one_line(tmp_path, capsys):
    first, second, sweep = tmp_path / "first", tmp_path / "second", tmp_path / "sweep"
    for folder in (first, second, sweep):
        folder.mkdir()
    # The same run_id, as `grits-lab evaluate --output-dir` keeps it: the same DP episode in both runs.
    pd.DataFrame([episode("dp", "sago", "low", 0, "success", run_id="evaluate")]).to_parquet(first / "episodes.parquet", index=False)
    pd.DataFrame([episode("dp", "sago", "low", 0, "spill", run_id="evaluate"),
                  episode("dp", "sago", "low", 1, "spill", run_id="evaluate")]).to_parquet(second / "episodes.parquet", index=False)
    pd.DataFrame([episode("grits", "sago", "low", 0, "success", rho=1.0, s=30)]).to_parquet(sweep / "trial_00000.parquet", index=False)
    pd.DataFrame({"number": [0], "state": ["COMPLETE"], "rho": [1.0], "s": [30],
                  "success_rate": [1.0], "spillage_rate": [0.0]}).to_parquet(sweep / "trials.parquet", index=False)
    out = tmp_path / "out"
    cases = [
        ([first, second], "hold the same episode"),
        ([first, first], "given twice"),
        ([first, sweep], "is a sweep"),
        ([sweep, first], "is a sweep"),
        ([first, out / "shard.parquet"], "the report's output directory"),
    ]
    out.mkdir()
    pd.DataFrame([episode("bc", "sago", "low", 0, "success")]).to_parquet(out / "shard.parquet", index=False)
    for runs, message in cases:
        assert main(["report", *map(str, runs), "--output-dir", str(out)]) == 2, message
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and message in err
    assert sorted(p.name for p in out.iterdir()) == ["shard.parquet"]  # nothing was written
