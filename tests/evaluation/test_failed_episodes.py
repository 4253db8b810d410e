"""`grits-lab evaluate` whose episodes raise: every record is written (errors kept), a rerun skips them
as finished, and the command exits 1 with one line naming how many failed and the first error."""

from __future__ import annotations

import pandas as pd
import pytest
import yaml

from grits_lab.cli import main
from studies.outcome_sensitivity.__main__ import main as study_main
from tests.sim.test_unsettled_food import BOULDERS

NUDGE = ["--offset", "0.0005", "--draw", "1"]


@pytest.mark.parametrize("nudge", [[], NUDGE], ids=["plain", "nudged"])
def test_evaluate_with_episodes_that_raise_keeps_their_records_and_exits_1_in_one_line(nudge, tmp_path, capsys):
    """A run with a scoop hook (the study's nudge) records its columns on its failed episodes too, so the
    rerun resumes it instead of refusing the records as another setting's."""
    foods = tmp_path / "boulders.yaml"
    foods.write_text(BOULDERS)  # six 5 cm spheres: every reset refuses them
    run = tmp_path / "run"
    config = tmp_path / "evaluate.yaml"
    config.write_text(yaml.safe_dump({
        "run_id": "boulders", "output_dir": str(run), "seed": 0, "methods": ["rule_based"], "foods": ["boulders"],
        "levels": ["low"], "trials": 2, "sim": {"foods_file": str(foods)},
    }))
    records_path = run / "episodes.parquet"
    first = None
    for attempt in range(2):  # the second run resumes: nothing left to run, the same records, the same exit
        code = (study_main(["nudge", str(config), *nudge, "--serial", "--no-progress"]) if nudge
                else main(["evaluate", str(config), "--serial", "--no-progress"]))
        out, err = capsys.readouterr()
        assert code == 1, out + err
        lines = err.strip().splitlines()
        assert len(lines) == 1, err
        assert lines[0].startswith(f"grits-lab: error: 2 of 2 episodes failed (records kept in {records_path}); "
                                   "the first, rule_based on boulders low trial 0: InputError: food 'boulders' (level 'low', seed "), lines[0]
        assert "particles came to rest outside the source bowl" in lines[0]
        records = pd.read_parquet(records_path)
        assert sorted(records["trial"]) == [0, 1]
        assert records["error"].str.contains("came to rest outside the source bowl").all()
        assert (records["scoop_action_offset_m"] == (0.0005 if nudge else 0.0)).all()
        assert (records["scoop_action_offset_draw"] == (1 if nudge else 0)).all()
        assert " err" in out and "rule_based" in out  # the summary table still printed, on stdout
        if first is not None:  # nothing re-run: the very records of the first run (wall times included)
            pd.testing.assert_frame_equal(records, first)
        first = records


def test_failed_records_of_earlier_code_without_scoop_columns_are_run_again_under_the_configs_setting(tmp_path, capsys):
    """Earlier code wrote no scoop hook columns on a failed episode's record: such a record says
    nothing of the setting it failed under, so the episode runs again under the run's (its row
    replaced, not doubled); a finished record of another setting is still refused."""
    foods = tmp_path / "boulders.yaml"
    foods.write_text(BOULDERS)
    run = tmp_path / "run"
    config = tmp_path / "evaluate.yaml"
    config.write_text(yaml.safe_dump({
        "run_id": "boulders", "output_dir": str(run), "seed": 0, "methods": ["rule_based"], "foods": ["boulders"],
        "levels": ["low"], "trials": 1, "sim": {"foods_file": str(foods)},
    }))
    nudged = ["nudge", str(config), "--offset", "0.0005", "--serial", "--no-progress"]
    assert study_main(nudged) == 1
    records_path = run / "episodes.parquet"
    old = pd.read_parquet(records_path).drop(columns=["scoop_action_offset_m", "scoop_action_offset_draw",
                                                       "scoop_branch_plan", "scoop_branch_draw"])
    old.to_parquet(records_path)
    capsys.readouterr()
    assert study_main(nudged) == 1  # run again: the same failure, nothing refused
    assert "episodes failed" in capsys.readouterr().err
    again = pd.read_parquet(records_path)
    assert len(again) == 1 and again.loc[0, "scoop_action_offset_m"] == 0.0005  # now under the run's nudge
    old.assign(error="").to_parquet(records_path)  # a finished episode without the columns ran with no offset
    assert study_main(nudged) == 2
    assert "scoop_action_offset_m 0, " in capsys.readouterr().err
