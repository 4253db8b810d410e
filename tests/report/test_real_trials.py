"""Real-robot trials beside the simulation: the documented CSV schema, the paper's numbers as such a
file, one table with the simulation, a lab's trials and the paper, and bad files refused in one line."""

from __future__ import annotations

import re

import pandas as pd
import pytest

from grits_lab.cli import main
from grits_lab.errors import InputError
from grits_lab.report.real_trials import PAPER_FILE, read_real_trials, real_counts
from grits_lab.report.vocabulary import PAPER_RESULTS
from tests.report.synthetic_records import episode


def test_the_paper_ships_as_aggregate_rows_that_give_its_stated_rates():
    counts = real_counts(read_real_trials(PAPER_FILE)).set_index("method")
    assert counts.loc["grits", ["task_success_k", "spillage_k", "scoop_failure_k"]].tolist() == [82, 4, 14]
    assert counts.loc["grits", "task_success_n"] == 100
    assert counts.loc["dp_post", "task_success_n"] == 0  # the paper states no task success for DP (Post.)
    assert PAPER_RESULTS == {"grits": {"task_success": 0.82, "spillage": 0.04, "scoop_failure": 0.14},
                             "dp_post": {"spillage": 0.08, "scoop_failure": 0.40}}


def test_a_labs_trials_sit_beside_the_simulation_and_the_paper_in_one_table(tmp_path):
    run, out = tmp_path / "run", tmp_path / "out"
    run.mkdir()
    pd.DataFrame([episode("grits", "sago", "low", t, "success" if t < 3 else "spill") for t in range(4)]).to_parquet(run / "episodes.parquet")
    lab = tmp_path / "lab.csv"
    lab.write_text("method,food,level,trial,task_success,spillage,scoop_failure\n"
                   "grits,sago,low,0,true,false,false\ngrits,sago,low,1,1,0,0\ngrits,sago,low,2,false,true,false\n"
                   "dp,sago,low,0,false,true,false\n")
    assert main(["report", str(run), "--real", str(lab), "--output-dir", str(out)]) == 0
    table = pd.read_csv(out / "csv" / "real_robot.csv")
    grits = table[table["method"] == "grits"].set_index("source")
    assert list(grits.index) == ["simulation", "real robot (lab)", "real robot (paper)"]
    assert grits.loc["simulation", "task_success_k"] == 3 and grits.loc["simulation", "task_success_n"] == 4
    assert grits.loc["real robot (lab)", "task_success_k"] == 2 and grits.loc["real robot (lab)", "spillage_k"] == 1
    assert grits.loc["real robot (paper)", "task_success_k"] == 82 and grits.loc["real robot (paper)", "task_success_n"] == 100
    assert table[table["method"] == "dp"]["source"].tolist() == ["real robot (lab)"]  # a method only the lab ran
    assert "Real robot beside the simulation" in (out / "report.md").read_text()


@pytest.mark.parametrize("text, message", [
    ("method,food,level,trial,task_success,spillage\n", "lack the columns scoop_failure"),
    ("method,food,level,trial,task_success,spillage,scoop_failure,robot\n", "unknown column `robot`"),
    ("method,food,level,trial,task_success,spillage,scoop_failure\ngrits,sago,low,0,maybe,0,0\n", "lab.csv:2: `task_success` must be a whole number"),
    ("method,food,level,trial,task_success,spillage,scoop_failure\ngrits,sago,low,0,2,0,0\n", "counts 2 of 1 trials"),
    ("method,food,level,trial,task_success,spillage,scoop_failure,trials\ngrits,all,all,,90,4,14,80\n", "counts 90 of 80 trials"),
])
def test_a_bad_trials_file_is_one_line_before_the_report_is_written(tmp_path, capsys, text, message):
    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame([episode("dp", "sago", "low", 0, "success")]).to_parquet(run / "episodes.parquet")
    (tmp_path / "lab.csv").write_text(text)
    with pytest.raises(InputError, match=message):
        read_real_trials(tmp_path / "lab.csv")
    assert main(["report", str(run), "--real", str(tmp_path / "lab.csv"), "--output-dir", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.count("\n") == 1 and not (tmp_path / "out").exists()


HEADER = "method,food,level,trial,task_success,spillage,scoop_failure"


@pytest.mark.parametrize("name, text, message", [
    ("paper.csv", f"{HEADER}\ngrits,sago,low,0,true,false,false\n",
     r"paper.csv: the source `paper` is the name of the paper's shipped numbers; add a `source` column"),
    ("lab.csv", f"{HEADER}\ngrits,sago,low,0,true,false,false\ngrits,sago,low,0,false,true,false\n",
     r"lab.csv:3: trial 0 of grits on sago low is listed already on line 2"),
    ("lab.csv", f"{HEADER}\ngritz,sago,low,0,true,false,false\n", r"lab.csv:2: unknown method `gritz`; one of .*grits"),
    ("lab.csv", f"{HEADER}\ngrits,sago,low,0,true,true,false\n",
     r"lab.csv:2: a trial with `task_success` cannot have `spillage`"),
    ("lab.csv", f"{HEADER},trials\ngrits,all,all,,90,4,14,100\n",
     r"lab.csv:2: `task_success` 90 and `scoop_failure` 14 add up to more than 100 trials"),
    ("lab.csv", f"{HEADER}\ngrits,sago,low,,true,false,false\n", r"lab.csv:2: `trial` is empty on a row of one trial"),
])
def test_a_real_trials_file_that_would_miscount_is_refused_in_one_line(tmp_path, capsys, name, text, message):
    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame([episode("grits", "sago", "low", 0, "success")]).to_parquet(run / "episodes.parquet")
    (tmp_path / name).write_text(text)
    assert main(["report", str(run), "--real", str(tmp_path / name), "--output-dir", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(message, err[0]), err
    assert not (tmp_path / "out").exists()


def test_a_trials_file_given_twice_or_two_files_of_one_source_are_refused(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    pd.DataFrame([episode("grits", "sago", "low", 0, "success")]).to_parquet(run / "episodes.parquet")
    (tmp_path / "a").mkdir()
    for folder in (tmp_path, tmp_path / "a"):
        (folder / "lab.csv").write_text(f"{HEADER}\ngrits,sago,low,0,true,false,false\n")
    for files, message in (([tmp_path / "lab.csv", tmp_path / "lab.csv"], "is given twice"),
                           ([tmp_path / "lab.csv", tmp_path / "a" / "lab.csv"], "both hold trials of the source `lab`")):
        assert main(["report", str(run), *[a for f in files for a in ("--real", str(f))], "--output-dir", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
        assert not (tmp_path / "out").exists()


def test_the_simulation_beside_a_labs_trials_counts_only_the_episodes_of_its_foods_and_levels(tmp_path):
    run, out = tmp_path / "run", tmp_path / "out"
    run.mkdir()
    rows = [episode("grits", "sago", "low", t, "success") for t in range(3)]
    rows += [episode("grits", "cereal", "high", t, "spill") for t in range(5)]
    pd.DataFrame(rows).to_parquet(run / "episodes.parquet")
    lab = tmp_path / "lab.csv"
    lab.write_text(f"{HEADER}\ngrits,sago,low,0,true,false,false\ngrits,sago,low,1,false,true,false\n")
    assert main(["report", str(run), "--real", str(lab), "--output-dir", str(out)]) == 0
    table = pd.read_csv(out / "csv" / "real_robot.csv")
    grits = table[table["method"] == "grits"]
    assert grits["source"].tolist() == ["simulation (as lab)", "real robot (lab)", "simulation", "real robot (paper)"]
    assert grits["selection"].tolist() == ["sago low", "sago low", "all foods and levels", "all foods and levels"]
    assert grits["task_success_n"].tolist()[::2] == [3, 8] and grits["task_success_k"].tolist()[::2] == [3, 3]
    page = (out / "report.md").read_text()
    assert "simulation (as lab): the simulated episodes of sago low, the foods and levels of the trials of lab" in page
