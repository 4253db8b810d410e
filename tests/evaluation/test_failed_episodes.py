"""`grits-lab evaluate` whose episodes raise: every record is written (errors kept), a rerun skips them
as finished, and the command exits 1 with one line naming how many failed and the first error."""

from __future__ import annotations

import pandas as pd
import yaml

from grits_lab.cli import main
from tests.sim.test_unsettled_food import BOULDERS


def test_evaluate_with_episodes_that_raise_keeps_their_records_and_exits_1_in_one_line(tmp_path, capsys):
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
        code = main(["evaluate", str(config), "--serial", "--no-progress"])
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
        assert " err" in out and "rule_based" in out  # the summary table still printed, on stdout
        if first is not None:  # nothing re-run: the very records of the first run (wall times included)
            pd.testing.assert_frame_equal(records, first)
        first = records
