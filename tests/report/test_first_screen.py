"""The report's first screen: what ran, every rate with its Wilson interval, a verdict only where the
intervals are apart, a title naming the experiment, and GRITS marked when its predictor cannot steer."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from grits_lab.report import build_report, normalize_records
from grits_lab.report.guidance_effect import plan_effect, plan_effect_line
from grits_lab.report.headline import NOTHING_TO_ACT_ON, decision_sentence, episodes_sentence, headline_table
from tests.report.synthetic_records import episode


def _run(dp_spills: int, grits_spills: int, n: int, run_id: str = "synthetic") -> pd.DataFrame:
    rows = [episode(m, "penne", "high", i, "spill" if i < k else "success", run_id=run_id)
            for m, k in (("dp", dp_spills), ("grits", grits_spills)) for i in range(n)]
    return normalize_records(pd.DataFrame(rows))


def test_one_spill_against_one_in_four_episodes_is_undecided():
    table = headline_table(_run(1, 1, 4))
    assert table.display.set_index("Method").loc["GRITS", "Spillage"] == "25.0% [4.6, 69.9] (1/4)"
    sentence = decision_sentence(table)
    assert "spillage: undecided at n = 4" in sentence and "decided," not in sentence


def test_intervals_apart_decide_and_name_the_lower_method():
    sentence = decision_sentence(headline_table(_run(30, 2, 40)))  # 75 % [59.8, 85.8] against 5 % [1.4, 16.5]
    assert "spillage: decided, GRITS lower (Wilson 95% intervals apart)" in sentence


def test_the_first_screen_says_which_foods_levels_and_seeds_ran():
    records = _run(0, 0, 2)
    text = episodes_sentence(records)
    seeds = sorted(records["seed"].unique())
    assert "foods penne (unseen)" in text and "levels high" in text and "trials 0, 1" in text
    assert f"2 episode seeds ({seeds[0]}, {seeds[1]})" in text and "2 episodes per method." in text
    crashed = normalize_records(pd.DataFrame([episode("dp", "penne", "high", 0, "success", error="OutOfMemoryError")]))
    assert "1 ended in an error, counted as a failed task" in episodes_sentence(crashed)


def test_the_title_names_the_experiment_and_protocol_not_the_folder(tmp_path):
    run = tmp_path / "evaluate"
    run.mkdir()
    _run(1, 1, 4, run_id="quickstart").to_parquet(run / "episodes.parquet", index=False)
    page = (build_report(run).out_dir / "report.md").read_text()
    first = page.splitlines()[0]
    assert first.startswith("# GRITS reproduction report: quickstart, protocol ") and "evaluate" not in first


def _guided(unguided: list[list[float]], guided: list[list[float]], moved: list[list[float]]) -> pd.DataFrame:
    return pd.DataFrame({"variant": "grits", "variant_name": "GRITS", "plan_p_spill_unguided": [np.array(u) for u in unguided],
                         "plan_p_spill_guided": [np.array(g) for g in guided], "plan_displacement_mm": [np.array(m) for m in moved]})


def test_the_guidance_line_gives_the_median_p_spill_over_every_plan_and_the_displacement():
    effect = plan_effect(_guided([[0.4, 0.2], [0.3]], [[0.3, 0.1], [0.2]], [[2.0, 4.0], [3.0]]))["grits"]
    assert effect["plans"] == 3 and effect["p_spill_unguided"] == 0.3 and effect["p_spill_guided"] == 0.2
    assert np.isclose(effect["relative_change"], -1 / 3) and effect["displacement_mm"] == 3.0
    assert "0.300 -> executed 0.200 (-33.3 %) over 3 plans" in plan_effect_line(effect)


def test_a_predictor_whose_p_spill_barely_varies_marks_grits_as_having_nothing_to_act_on(tmp_path):
    run, predictor = tmp_path / "evaluate", tmp_path / "predictor" / "predictor"
    run.mkdir()
    predictor.mkdir(parents=True)
    _run(1, 1, 4).to_parquet(run / "episodes.parquet", index=False)
    history = [{"epoch": 1, "val_loss": 0.5, "val_auroc": 0.87, "val_n": 21, "val_spill_rate": 0.19, "val_ece": 0.02,
                "val_positives": 4, "val_p_spill_std": 0.003}]
    (predictor / "history.json").write_text(json.dumps(history))
    result = build_report(run, training=[tmp_path / "predictor"])
    headline = next(t for t in result.tables if t.key == "headline").display.set_index("Method")
    assert headline.loc["GRITS", "Note"].startswith(NOTHING_TO_ACT_ON) and headline.loc["Diffusion Policy", "Note"] == ""
    page = (result.out_dir / "report.md").read_text()
    assert "Predictor `predictor` (label chunk, class weight none): validation AUROC 0.87 on 21 chunks (4 spilling)" in page
