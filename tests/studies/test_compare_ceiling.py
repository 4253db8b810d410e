"""`python -m studies.outcome_sensitivity compare`: two runs paired, with each outcome's AUROC ceiling
where they are two draws of one chance (a nudge, other CPU kernels, or declared)."""

from __future__ import annotations

import pandas as pd

from studies.outcome_sensitivity.__main__ import main as study_main
from tests.report.test_run_compare import _run


def test_a_run_with_offset_scoop_actions_is_named_in_the_caption(tmp_path, capsys):
    _run([("success", 40, 0), ("spill", 40, 0)], tmp_path, "base")  # records from before the column: no offset
    moved = _run([("spill", 40, 0), ("spill", 40, 0)], tmp_path, "moved").assign(scoop_action_offset_m=0.0005)
    moved.to_parquet(tmp_path / "moved" / "episodes.parquet")
    assert study_main(["compare", str(tmp_path / "base"), str(tmp_path / "moved"), "--output-dir", str(tmp_path / "cmp")]) == 0
    out = capsys.readouterr().out
    assert "| Diffusion Policy | 2 | 1/2 |" in out
    assert "offset (`scoop_action_offset_m`): 0 mm in base, 0.5 mm in moved" in out
    assert "| Diffusion Policy | spill during the scoop | 75% | 1/2 |" in out  # 1 + 2 of 4 runs; trial 0 changed
    table = pd.read_csv(tmp_path / "cmp" / "comparison.csv").set_index("method")
    assert (table.loc["dp", "action_offset_before_m"], table.loc["dp", "action_offset_after_m"]) == (0.0, 0.0005)
    assert study_main(["compare", str(tmp_path / "base"), str(tmp_path / "base")]) == 0
    assert "action_offset" not in (out := capsys.readouterr().out) and "AUROC ceiling" not in out


def test_runs_on_other_cpu_kernels_are_named_and_get_the_ceiling(tmp_path, capsys):
    wide, narrow = "numpy X86_V3+X86_V4; openblas SkylakeX; torch AVX512", "numpy X86_V3; openblas Haswell; torch AVX2"
    _run([("success", 40, 0), ("spill", 40, 0)], tmp_path, "here").assign(cpu_kernels=wide).to_parquet(tmp_path / "here" / "episodes.parquet")
    _run([("spill", 40, 0), ("spill", 40, 0)], tmp_path, "there").assign(cpu_kernels=narrow).to_parquet(tmp_path / "there" / "episodes.parquet")
    assert study_main(["compare", str(tmp_path / "here"), str(tmp_path / "there"), "--output-dir", str(tmp_path / "cmp")]) == 0
    out = capsys.readouterr().out
    assert f"2 of 2 pairs ran on other CPU kernels, e.g. `{wide}` in here, `{narrow}` in there" in out
    assert "| Outcome | Rate, both runs | Changed by the kernels |" in out
    assert "| Diffusion Policy | spill during the scoop | 75% | 1/2 |" in out
    table = pd.read_csv(tmp_path / "cmp" / "comparison.csv").set_index("method")
    assert table.loc["dp", "kernels_differ"] == 2 and table.loc["dp", "cpu_kernels_after"] == narrow
    # The same kernels, or a run that did not record them, claim nothing.
    assert study_main(["compare", str(tmp_path / "here"), str(tmp_path / "here")]) == 0
    assert "CPU kernels" not in (out := capsys.readouterr().out) and "AUROC ceiling" not in out
    _run([("spill", 40, 0), ("spill", 40, 0)], tmp_path, "older")
    assert study_main(["compare", str(tmp_path / "here"), str(tmp_path / "older")]) == 0
    assert "CPU kernels" not in (out := capsys.readouterr().out) and "AUROC ceiling" not in out


def test_two_runs_nudged_along_other_draws_are_two_tosses(tmp_path, capsys):
    _run([("success", 40, 0), ("spill", 40, 0)], tmp_path, "draw0").assign(
        scoop_action_offset_m=0.0005, scoop_action_offset_draw=0).to_parquet(tmp_path / "draw0" / "episodes.parquet")
    _run([("spill", 40, 0), ("spill", 40, 0)], tmp_path, "draw1").assign(
        scoop_action_offset_m=0.0005, scoop_action_offset_draw=1).to_parquet(tmp_path / "draw1" / "episodes.parquet")
    assert study_main(["compare", str(tmp_path / "draw0"), str(tmp_path / "draw1")]) == 0
    out = capsys.readouterr().out
    assert "offset (`scoop_action_offset_m`): 0.5 mm (draw 0) in draw0, 0.5 mm (draw 1) in draw1" in out
    assert "| Diffusion Policy | spill during the scoop | 75% | 1/2 |" in out
    assert study_main(["compare", str(tmp_path / "draw1"), str(tmp_path / "draw1")]) == 0
    assert "AUROC ceiling" not in capsys.readouterr().out  # one draw against itself is one toss


def test_a_declared_ceiling_pairs_runs_whose_records_do_not_name_their_difference(tmp_path, capsys):
    _run([("success", 40, 0), ("spill", 40, 0)], tmp_path, "one")
    _run([("spill", 40, 0), ("spill", 40, 0)], tmp_path, "two")
    assert study_main(["compare", str(tmp_path / "one"), str(tmp_path / "two")]) == 0
    assert "AUROC ceiling" not in capsys.readouterr().out
    assert study_main(["compare", str(tmp_path / "one"), str(tmp_path / "two"), "--declared", "--output-dir", str(tmp_path / "cmp")]) == 0
    out = capsys.readouterr().out
    assert "compared as two draws of one chance (`--declared`)" in out
    assert "| Diffusion Policy | spill during the scoop | 75% | 1/2 |" in out and "Changed by the difference between the runs" in out
    assert bool(pd.read_csv(tmp_path / "cmp" / "comparison.csv")["ceiling_declared"].iloc[0])
