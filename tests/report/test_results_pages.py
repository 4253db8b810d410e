"""Results are generated, not written: an experiment's summary counts what its records hold, and the
README, docs/results.md and the experiment pages are rendered from the committed summaries."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest

from grits_lab.cli import main
from grits_lab.errors import InputError
from grits_lab.report.results_pages import drifted, provenance_block, render_all, write_all
from grits_lab.sim.spill_metrics import attribution_columns
from tests.report.synthetic_records import episode

ROOT = Path(__file__).resolve().parents[2]


def test_the_committed_pages_match_their_summaries():
    stale = drifted(ROOT)
    assert not stale, (f"{', '.join(str(p.relative_to(ROOT)) for p in stale)} differ from studies/*/summaries/*/summary.csv: "
                       "run `grits-lab results render` (a new run: `grits-lab report RUN_DIR --summary-to studies/s/summaries/NAME` first)")
    assert ROOT / "README.md" in render_all(ROOT) and ROOT / "docs" / "results.md" in render_all(ROOT)


def _records(tmp_path: Path) -> Path:
    """dp: 3 episodes (1 success, 1 spill in the scoop, 1 carry loss); grits: 1 episode with an error."""
    rows = []
    for trial, (outcome, lost, transferred) in enumerate([("success", {}, 20), ("spill", {"spilled_scoop_over_rim": 2}, 20),
                                                          ("transfer_fail", {"spilled_carry_off_spoon": 3}, 10)]):
        row = episode("dp", "sago", "low", trial, outcome)
        row.update({c: 0 for c in attribution_columns()}, **lost, transferred=transferred)
        rows.append(row)
    row = episode("grits", "sago", "low", 0, "success", error="boom")
    row.update({c: 0 for c in attribution_columns()})
    rows.append(row)
    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame(rows).to_parquet(run / "episodes.parquet")
    (run / "config.yaml").write_text("run_id: synthetic\n")
    (run / "provenance.json").write_text(json.dumps({"code git commit": "abc123", "host": "box", "started (UTC)": "2026-01-02 03:04:05",
                                                     "packages": {"python": "3.11.7"}}))
    return run


def test_the_summary_counts_what_the_records_hold_with_wilson_intervals(tmp_path, capsys):
    run = _records(tmp_path)
    out = tmp_path / "studies" / "s" / "summaries" / "tiny"
    assert main(["report", str(run), "--output-dir", str(tmp_path / "report"), "--summary-to", str(out)]) == 0
    summary = pd.read_csv(out / "summary.csv").set_index(["method", "outcome"])
    assert summary.loc[("dp", "task_success"), ["k", "n"]].tolist() == [1, 3]
    assert summary.loc[("dp", "spillage"), ["k", "n"]].tolist() == [1, 3]
    assert summary.loc[("dp", "spill_after_scoop"), ["k", "n"]].tolist() == [1, 3]
    assert summary.loc[("dp", "spill_carry"), "k"] == 1 and summary.loc[("dp", "spill_pour"), "k"] == 0
    assert summary.loc[("dp", "delivered"), ["k", "n"]].tolist() == [2, 3]  # the carry's loss is not delivered
    assert summary.loc[("dp", "task_success"), ["ci_low", "ci_high"]].tolist() == [0.061492, 0.79234]  # Wilson, 1 of 3
    assert summary.loc[("grits", "error"), ["k", "n"]].tolist() == [1, 1]
    assert summary.loc[("grits", "task_success"), "k"] == 0  # an error is a failure
    stages = pd.read_csv(out / "stage_cause.csv").set_index(["method", "stage", "cause"])
    assert stages.loc[("dp", "carry", "off_spoon"), ["episodes_k", "episodes", "particles"]].tolist() == [1, 3, 3]
    provenance = json.loads((out / "provenance.json").read_text())
    assert provenance["methods"]["dp"]["episodes"] == 3 and provenance["methods"]["dp"]["trials"] == [0, 1, 2]
    assert provenance["records' code commit"] == "abc123" and provenance["machine"]["host"] == "box"
    assert provenance["protocol"] and provenance["episode wall time (s, summed)"] == 50.0
    assert (out / "config.yaml").read_text() == "run_id: synthetic\n" and (out / "claims.csv").is_file()


def test_rendering_replaces_only_the_generated_blocks_and_check_finds_the_drift(tmp_path, capsys):
    run = _records(tmp_path)
    assert main(["report", str(run), "--output-dir", str(tmp_path / "report"), "--summary-to",
                 str(tmp_path / "studies" / "s" / "summaries" / "tiny")]) == 0
    page = tmp_path / "studies" / "s" / "summaries" / "tiny" / "README.md"
    page.write_text("# Tiny: does it count?\n\nWritten by hand.\n\n<!-- generated: outcomes tiny -->\nold\n<!-- end generated -->\n\nAfter.\n")
    results = tmp_path / "docs" / "results.md"
    results.parent.mkdir(exist_ok=True)
    results.write_text("Intro.\n<!-- generated: headline tiny -->\n<!-- end generated -->\n<!-- generated: index -->\n<!-- end generated -->\n")
    capsys.readouterr()
    assert main(["results", "check", "--root", str(tmp_path)]) == 1
    assert "studies/s/summaries/tiny/README.md differs from its summaries" in capsys.readouterr().out
    assert sorted(write_all(tmp_path)) == sorted([page, results]) and not drifted(tmp_path)
    text = page.read_text()
    assert text.startswith("# Tiny: does it count?\n\nWritten by hand.\n") and text.endswith("<!-- end generated -->\n\nAfter.\n")
    assert "| Diffusion Policy | 3 | 33.3% [6.1%, 79.2%] (1/3) |" in text and "old" not in text
    index = results.read_text()
    assert "| [tiny](../studies/s/summaries/tiny/README.md) | Tiny: does it count? |" in index
    assert "| GRITS | 1 | 0.0% (0/1) | 82.0% |" in index  # the paper's number beside the simulation's
    assert main(["results", "check", "--root", str(tmp_path)]) == 0


def test_a_block_names_the_command_that_writes_a_missing_summary_and_refuses_an_unknown_experiment(tmp_path):
    (tmp_path / "studies" / "s" / "summaries" / "later").mkdir(parents=True)
    results = tmp_path / "docs" / "results.md"
    results.parent.mkdir(exist_ok=True)
    results.write_text("<!-- generated: outcomes later -->\n<!-- end generated -->\n")
    assert "No summary yet: `grits-lab report RUN_DIR --summary-to studies/s/summaries/later`" in render_all(tmp_path)[results]
    results.write_text("<!-- generated: outcomes nothing -->\n<!-- end generated -->\n")
    with pytest.raises(InputError, match=r"no experiment `nothing`: no folder of that name in studies/\*/summaries or docs/archive"):
        render_all(tmp_path)


def test_a_shift_block_sets_each_methods_counts_before_beside_after(tmp_path):
    run = _records(tmp_path)
    docs = tmp_path / "studies" / "s" / "summaries"
    assert main(["report", str(run), "--output-dir", str(tmp_path / "r1"), "--summary-to", str(docs / "before")]) == 0
    after = pd.read_parquet(run / "episodes.parquet")
    after = after[after["method"] == "dp"].copy()
    after["spilled_carry_off_spoon"] = 0  # the carry no longer loses food: that episode now succeeds
    after.loc[after["trial"] == 2, ["outcome", "task_success", "transferred"]] = ["success", True, 20]
    (tmp_path / "run2").mkdir()
    after.to_parquet(tmp_path / "run2" / "episodes.parquet")
    assert main(["report", str(tmp_path / "run2"), "--output-dir", str(tmp_path / "r2"), "--summary-to", str(docs / "after")]) == 0
    (docs / "after" / "README.md").write_text("# After\n\n<!-- generated: shift before..after -->\n<!-- end generated -->\n")
    page = render_all(tmp_path)[docs / "after" / "README.md"]
    # dp: success 1/3 → 2/3, carry 1/3 → 0/3; grits is in no after run, so it has no row.
    assert "| Diffusion Policy | 1/3 → 2/3 | 1/3 → 1/3 | 0/3 → 0/3 | 1/3 → 0/3 | 0/3 → 0/3 | 1/3 → 0/3 |" in page
    assert "GRITS" not in page.split("<!-- end generated -->")[0].split("shift before..after")[1]
    # Methods missing from the first run after are taken from the next: grits from `before` itself.
    (docs / "after" / "README.md").write_text("<!-- generated: shift before..after+before -->\n<!-- end generated -->\n")
    page = render_all(tmp_path)[docs / "after" / "README.md"]
    assert "| Diffusion Policy | 1/3 → 2/3 |" in page and "| GRITS | 0/1 → 0/1 |" in page and "[before](../before/README.md)" in page
    # A headline over several experiments takes each method from the first that holds it.
    (docs / "after" / "README.md").write_text("<!-- generated: headline after+before -->\n<!-- end generated -->\n")
    page = render_all(tmp_path)[docs / "after" / "README.md"]
    assert "| Diffusion Policy | 3 | 66.7% (2/3) |" in page and "| GRITS | 1 | 0.0% (0/1) |" in page
    (docs / "after" / "README.md").write_text("<!-- generated: shift before -->\n<!-- end generated -->\n")
    with pytest.raises(InputError, match="BEFORE..AFTER"):
        render_all(tmp_path)


def test_a_page_is_a_run_the_report_reads_so_a_protocol_split_across_sittings_is_reported_as_one(tmp_path):
    """Trials 0-2 summarized to a page, trials 3-4 run later: the page and the new run reported together
    give every table the whole run gives, and the page keeps the records it counted."""
    from tests.report.synthetic_records import plausible_run

    records = plausible_run(seed=3)
    records = records[records["method"].isin(["dp", "grits", "dp_post"])].copy()
    records["checkpoint_policy"] = "9d42be08670d9975"
    attribution = list(attribution_columns())
    records[attribution] = 0
    records.loc[records["spillage"], attribution[0]] = 4
    records.loc[records.index[5], "error"] = "IK failed to converge"  # an errored episode survives the round trip
    records.loc[records.index[5], "task_success"] = False
    runs = {}
    for name, rows in (("whole", records), ("first", records[records["trial"] <= 2]), ("later", records[records["trial"] > 2])):
        runs[name] = tmp_path / name
        runs[name].mkdir()
        rows.to_parquet(runs[name] / "episodes.parquet")
    docs = tmp_path / "studies" / "s" / "summaries"
    assert main(["report", str(runs["whole"]), "--output-dir", str(tmp_path / "r0"), "--summary-to", str(docs / "whole")]) == 0
    assert main(["report", str(runs["first"]), "--output-dir", str(tmp_path / "r1"), "--summary-to", str(docs / "first")]) == 0
    page = pd.read_csv(docs / "first" / "episodes.csv")
    assert len(page) == int((records["trial"] <= 2).sum()) and set(page["trial"]) == {0, 1, 2}
    assert main(["report", str(runs["later"]), str(docs / "first"), "--output-dir", str(tmp_path / "r2"),
                 "--summary-to", str(docs / "joined")]) == 0
    for table in ("summary.csv", "stage_cause.csv", "paired.csv", "claims.csv"):
        assert (docs / "joined" / table).read_text() == (docs / "whole" / table).read_text(), table
    joined = json.loads((docs / "joined" / "provenance.json").read_text())
    assert joined["methods"]["dp"]["trials"] == [0, 1, 2, 3, 4] and joined["episodes"] == len(records)
    # The same episodes twice (the page beside the run it was made from) are refused, naming both.
    from grits_lab.report.run_records import load_run

    with pytest.raises(InputError, match="hold the same episode"):
        load_run(runs["first"], also=[docs / "first"])


def test_the_summary_counts_episodes_per_cpu_kernels_and_the_page_names_them(tmp_path):
    run = _records(tmp_path)
    frame = pd.read_parquet(run / "episodes.parquet")
    frame["cpu_kernels"] = ["numpy X86_V3; openblas Haswell"] * 3 + ["numpy X86_V3+X86_V4; openblas SkylakeX"]
    frame.to_parquet(run / "episodes.parquet")
    provenance = json.loads((run / "provenance.json").read_text())
    (run / "provenance.json").write_text(json.dumps({**provenance, "cpu": "AMD EPYC"}))
    out = tmp_path / "studies" / "s" / "summaries" / "tiny"
    assert main(["report", str(run), "--output-dir", str(tmp_path / "report"), "--summary-to", str(out)]) == 0
    machine = json.loads((out / "provenance.json").read_text())["machine"]
    assert machine["cpu"] == "AMD EPYC" and machine["host"] == "box"
    assert machine["cpu kernels (episodes)"] == {"numpy X86_V3+X86_V4; openblas SkylakeX": 1, "numpy X86_V3; openblas Haswell": 3}
    block = provenance_block(tmp_path, "tiny", out)
    assert ("; CPU AMD EPYC; CPU kernels `numpy X86_V3+X86_V4; openblas SkylakeX` (1 episode), "
            "`numpy X86_V3; openblas Haswell` (3 episodes); run started") in block


def test_a_per_food_block_counts_each_methods_outcomes_food_by_food_without_errored_episodes(tmp_path):
    from grits_lab.report.run_records import load_run
    from grits_lab.report.summary import write_summary

    # dp: sago spills in the scoop once of 2, red bean loses food in the carry; grits: no spill, one error on red bean.
    rows = []
    for method, food, trial, outcome, lost, error in (
            ("dp", "sago", 0, "spill", {"spilled_scoop_over_rim": 2}, ""), ("dp", "sago", 1, "success", {}, ""),
            ("dp", "red_bean", 0, "transfer_fail", {"spilled_carry_off_spoon": 3}, ""),
            ("grits", "sago", 0, "success", {}, ""), ("grits", "sago", 1, "success", {}, ""),
            ("grits", "red_bean", 0, "success", {}, "boom"), ("rule_based", "sago", 0, "success", {}, "boom")):
        row = episode(method, food, "brim", trial, outcome, error=error)
        row.update({c: 0 for c in attribution_columns()}, **lost)
        rows.append(row)
    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame(rows).to_parquet(run / "episodes.parquet")
    folder = tmp_path / "studies" / "s" / "summaries" / "foods"
    write_summary(load_run(run), folder, "grits-lab report run --summary-to studies/s/summaries/foods")
    (folder / "README.md").write_text("# Foods\n\n<!-- generated: per_food foods -->\n<!-- end generated -->\n")
    page = render_all(tmp_path)[folder / "README.md"]
    scoop, before_pour, success = page.split("*Spill during the scoop*")[1], page.split("*Spill before the pour*")[1], page.split("*Task success*")[1]
    assert "| RB red bean | — | 0/1 | — |" in scoop  # the errored episode is left out
    assert "| RB red bean | — | 1/1 | — |" in before_pour and "| Every food | — | 2/3 | 0/2 |" in before_pour
    assert "| SA sago | — | 1/2 | 2/2 |" in success
    assert scoop.index("SA sago") < scoop.index("RB red bean")  # the paper's food order
    # A method whose every episode ended with an error keeps its column, in the outcomes block's order.
    assert "| Food | Rule-based | Diffusion Policy | GRITS |" in scoop and "| SA sago | — | 1/2 | 0/2 |" in scoop


def test_the_page_names_the_code_each_methods_records_ran_not_only_the_latest_runs(tmp_path):
    run = _records(tmp_path)
    frame = pd.read_parquet(run / "episodes.parquet")
    first, second = "a" * 40, "b" * 40 + " (with uncommitted changes)"
    frame["code_commit"] = [first, first, second, None]  # grits's record predates the column
    frame.to_parquet(run / "episodes.parquet")
    out = tmp_path / "studies" / "s" / "summaries" / "tiny"
    assert main(["report", str(run), "--output-dir", str(tmp_path / "report"), "--summary-to", str(out)]) == 0
    methods = json.loads((out / "provenance.json").read_text())["methods"]
    assert methods["dp"]["code commits"] == [first, second] and "code commits" not in methods["grits"]
    block = provenance_block(tmp_path, "tiny", out)
    assert f"records' code: `{'a' * 12}`, `{'b' * 12} (with uncommitted changes)`." in block  # not provenance.json's abc123
    dp_line = next(line for line in block.splitlines() if line.startswith("- Diffusion Policy"))
    assert dp_line.endswith(f"; code `{'a' * 12}`, `{'b' * 12} (with uncommitted changes)`.")
    assert "; code" not in next(line for line in block.splitlines() if line.startswith("- GRITS"))


def test_without_commits_in_the_records_the_page_names_the_runs_provenance(tmp_path):
    run = _records(tmp_path)
    out = tmp_path / "studies" / "s" / "summaries" / "tiny"
    assert main(["report", str(run), "--output-dir", str(tmp_path / "report"), "--summary-to", str(out)]) == 0
    assert "records' code: `abc123`." in provenance_block(tmp_path, "tiny", out)


def test_the_summary_reads_the_code_commit_before_it_writes_into_the_page(tmp_path, monkeypatch):
    """A page lives in the checkout: read after the summary's own files, the commit would always
    read "with uncommitted changes"."""
    import grits_lab.report.summary as summary
    from grits_lab.report.run_records import load_run

    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame([episode("dp", "sago", "high", 0, "success")]).to_parquet(run / "episodes.parquet")
    page = tmp_path / "studies" / "s" / "summaries" / "commit"
    seen = []
    monkeypatch.setattr(summary, "git_commit", lambda: seen.append(sorted(p.name for p in page.glob("*"))) or "abc123")
    summary.write_summary(load_run(run), page, "grits-lab report run --summary-to studies/s/summaries/commit")
    assert seen == [[]]
    assert json.loads((page / "provenance.json").read_text())["summary code commit"] == "abc123"


def _chain(docs: Path, name: str, policy: str, dp_spills: int, grits_spills: int, only_dp: int, only_grits: int, p: float):
    """An experiment folder of one chain: DP and GRITS on 20 paired seeds, their spills and the sign test."""
    folder = docs / name
    folder.mkdir(parents=True)
    pd.DataFrame([{"reference": "dp", "method": "grits", "paired": 20, "spillage_before": dp_spills, "spillage_after": grits_spills,
                   "spillage_only_before": only_dp, "spillage_only_after": only_grits, "spillage_p": p}]).to_csv(folder / "paired.csv", index=False)
    pd.DataFrame([{"method": m, "method_name": m, "outcome": "spillage", "k": k, "n": 20, "rate": k / 20, "ci_low": 0.01, "ci_high": 0.5}
                  for m, k in (("dp", dp_spills), ("grits", grits_spills))]).to_csv(folder / "summary.csv", index=False)
    (folder / "provenance.json").write_text(json.dumps({"methods": {"dp": {"name": "Diffusion Policy", "levels": ["high", "low"], "foods": 2,
                                                                           "checkpoint digests (sha256, first 16)": {"policy": [policy]}}}}))


def test_the_answer_block_says_whether_grits_spills_less_by_how_much_and_on_how_many_chains_and_seeds(tmp_path):
    docs = tmp_path / "studies" / "protocol" / "summaries"
    _chain(docs, "one", "aaaa", dp_spills=9, grits_spills=1, only_dp=8, only_grits=0, p=0.0078)
    _chain(docs, "two", "bbbb", dp_spills=5, grits_spills=4, only_dp=3, only_grits=2, p=1.0)
    page = tmp_path / "docs" / "results.md"
    page.parent.mkdir()
    page.write_text("<!-- generated: answer one+two -->\n<!-- end generated -->\n")
    text = render_all(tmp_path)[page]
    assert "at the levels high, low? On 1 of 2 chains: the exact sign test on the same seeds gives p < 0.05 for fewer spills on 1 of 2 chains." in text
    assert "5.0% [1.0%, 50.0%] (1/20) against 45.0% [1.0%, 50.0%] (9/20) on [one](../studies/protocol/summaries/one/README.md) (paired 1 against 9, p 0.0078)" in text
    assert "On 2 chains" in text and "`aaaa`, `bbbb`" in text and "40 paired seeds (20, 20) of 2 unseen foods" in text
    page.write_text("<!-- generated: answer two -->\n<!-- end generated -->\n")
    assert "Not measurably" in render_all(tmp_path)[page]
    (docs / "two" / "paired.csv").write_text("reference,method,paired,spillage_before,spillage_after,spillage_p\ndp,dp_post,20,5,1,0.2\n")
    with pytest.raises(InputError, match=r"studies/protocol/summaries/two/paired.csv: no `grits` paired with `dp`"):
        render_all(tmp_path)


@pytest.mark.parametrize("page_text, fault", [
    ("<!-- generated: index -->\nold\n\nhand-written paragraph\n<!-- generated: index -->\nold\n<!-- end generated -->\n",
     r"README.md:1: `<!-- generated: index -->` has no `<!-- end generated -->` before the next block \(line 5\)"),
    ("<!-- generated: index -->\nold\n", r"README.md:1: `<!-- generated: index -->` has no `<!-- end generated -->`"),
    ("hand-written\n<!-- end generated -->\n", r"README.md:2: `<!-- end generated -->` closes no block"),
    ("<!-- generated:index -->\nold\n<!-- end generated -->\n", r"README.md:1: a block marker that does not parse"),
])
def test_a_page_whose_markers_do_not_pair_is_refused_by_render_and_check_and_nothing_is_written(tmp_path, capsys, page_text, fault):
    page = tmp_path / "README.md"
    page.write_text(page_text)
    for action in ("check", "render"):
        assert main(["results", action, "--root", str(tmp_path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and str(page) in err[0], err
        assert re.search(fault, err[0]), err
    assert page.read_text() == page_text
