"""The scoop convergence study (studies/scoop_convergence): the choice rule on synthetic records, its
refusals, one tiny real run, and the power calculation from the committed summaries."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest
import yaml

from grits_lab.intervals import wilson_interval
from grits_lab.seeding import derive_seed
from grits_lab.sim.spill_metrics import attribution_columns
from studies.scoop_convergence.__main__ import main
from studies.scoop_convergence.convergence import STUDY_FILE, choose, convergence_table, episodes_for_half_width
from tests.report.synthetic_records import episode

SETTINGS = {"coarse": {"time_step": 1 / 120, "solver_iterations": 30}, "middle": {"time_step": 1 / 240, "solver_iterations": 100},
            "fine": {"time_step": 1 / 480, "solver_iterations": 100}}


def _records(spills: int, cause: str, changed: int = 0, n: int = 40) -> pd.DataFrame:
    """`n` expert scoops on one food, the first `spills` of them spilling 3 particles by `cause`;
    with `changed`, the first `changed` outcomes flipped (a nudged run of the same seeds)."""
    rows = []
    for trial in range(n):
        spilled = (trial < spills) != (trial < changed)
        row = episode("expert", "brown_rice", "brim", trial, "spill" if spilled else "success", run_id="synthetic")
        row.update({c: 0 for c in attribution_columns()})
        row.update({"seed": derive_seed(7000, "brown_rice", "brim", trial), "scoop_steps": 60, "spilled": 3 if spilled else 0,
                    f"spilled_scoop_{cause}": 3 if spilled else 0})
        rows.append(row)
    return pd.DataFrame(rows)


def _study(tmp_path: Path, plain: dict[str, tuple[int, str]], changed: int, max_half_width: float = 0.1) -> Path:
    out = tmp_path / "study"
    for name, (spills, cause) in plain.items():
        for variant, flips in (("plain", 0), ("nudge0", changed)):
            (out / name / variant).mkdir(parents=True)
            _records(spills, cause, flips).to_parquet(out / name / variant / "episodes.parquet", index=False)
    study = {"evaluation": "studies/scoop_convergence/configs/evaluate_train_scoop.yaml", "settings": SETTINGS,
             "nudge": {"offset": 0.0005, "draws": [0]}, "decision": {"max_half_width": max_half_width}}
    (out / STUDY_FILE).write_text(yaml.safe_dump(study, sort_keys=False))
    return out


def test_the_coarsest_setting_within_the_finest_ones_intervals_is_chosen_and_undecided_at_small_n(tmp_path):
    """40 scoops a setting: the coarse one spills in 30 (all over the rim) against the fine one's 10 (off the
    spoon), the middle one in 11 off the spoon: the middle is chosen; +-0.1 is not reached at n 40."""
    out = _study(tmp_path, {"coarse": (30, "over_rim"), "middle": (11, "off_spoon"), "fine": (10, "off_spoon")}, changed=4)
    table, config = convergence_table(out)
    fine = table[table["setting"] == "fine"].iloc[0]
    assert (fine["episodes"], fine["spillage_k"], fine["off_spoon_k"], fine["over_rim_k"]) == (40, 10, 10, 0)
    assert (fine["nudge_change_k"], fine["nudge_change_n"]) == (4, 40)
    assert (fine["spillage_low"], fine["spillage_high"]) == pytest.approx(wilson_interval(10, 40))
    assert fine["spilled_sum"] == 30 and fine["spilled_scoop_off_spoon_sum"] == 30
    choice = choose(table, list(config.settings), "expert", 0.1)
    assert choice.chosen == "middle"
    assert set(choice.within["coarse"]) == {"spillage", "over_rim", "off_spoon"} and choice.within["middle"] == []
    assert not choice.decided and choice.widest == "spillage"
    assert choice.needed == episodes_for_half_width(0.25, 0.1) == math.ceil(1.959963984540054**2 * 0.25 * 0.75 / 0.01)
    assert "not decided at this n" in choice.sentence(0.1)
    assert choose(table, list(config.settings), "expert", 0.2).decided  # every fine half width at n 40 is below 0.2


def test_a_coarse_setting_within_every_interval_is_chosen_and_the_summary_is_written(tmp_path):
    out = _study(tmp_path, {"coarse": (12, "off_spoon"), "middle": (30, "over_rim"), "fine": (10, "off_spoon")}, changed=4)
    assert main(["summarize", str(out), "--summary-to", str(tmp_path / "summary")]) == 0
    text = (tmp_path / "summary" / "README.md").read_text()
    assert "**coarse**" in text and "middle: spill during the scoop, lost over the rim, lost off the spoon outside" in text
    written = pd.read_csv(tmp_path / "summary" / "convergence.csv")
    assert list(written["setting"]) == ["coarse", "coarse", "middle", "middle", "fine", "fine"]
    assert list(written["level"]) == ["all", "brim"] * 3
    assert (written["spillage_k"].iloc[::2].to_numpy() == written["spillage_k"].iloc[1::2].to_numpy()).all()  # one level: all = brim


def test_bad_input_is_one_line_and_exit_2_before_any_work(tmp_path, capsys):
    config = tmp_path / "one_setting.yaml"
    config.write_text(yaml.safe_dump({"evaluation": "studies/scoop_convergence/configs/evaluate_train_scoop.yaml",
                                      "settings": {"only": {"time_step": 1 / 120, "solver_iterations": 30}}}))
    assert main(["run", str(config), "--output-dir", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "settings" in err and "at least two" in err and not (tmp_path / "out").exists()
    shipped = "studies/scoop_convergence/configs/scoop_convergence_pilot.yaml"
    assert main(["run", shipped, "--output-dir", str(tmp_path / "out"), "--settings", "step60_iter30"]) == 2
    assert "not a setting of the config" in capsys.readouterr().err and not (tmp_path / "out").exists()
    assert main(["summarize", str(tmp_path), "--summary-to", str(tmp_path / "s")]) == 2
    assert "not a scoop convergence study" in capsys.readouterr().err
    config.write_text(yaml.safe_dump({"evaluation": "studies/scoop_convergence/configs/evaluate_train_scoop.yaml",
                                      "settings": SETTINGS}))  # sorted by name: fine before middle
    assert main(["run", str(config), "--output-dir", str(tmp_path / "out")]) == 2
    assert "coarsest first" in capsys.readouterr().err and not (tmp_path / "out").exists()
    assert main(["run", shipped, "--output-dir", str(tmp_path / "out"), "--methods", "expert", "dp"]) == 2
    assert "policy" in capsys.readouterr().err and not (tmp_path / "out").exists()


def test_one_tiny_real_scoop_at_the_coarse_setting_is_summarized_without_a_choice(models, tmp_path):
    """The expert's scoop of one food, one trial, the coarse setting only: a summary with its row and no choice."""
    from grits_lab.config import config_to_dict
    from tests.evaluation.eval_helpers import eval_config

    evaluation = tmp_path / "evaluation.yaml"
    data = config_to_dict(eval_config(models, tmp_path / "unused", methods=["expert"], transfer={"enabled": False}))
    evaluation.write_text(yaml.safe_dump(data))
    study = tmp_path / "study.yaml"
    study.write_text(yaml.safe_dump({"evaluation": str(evaluation), "settings": SETTINGS, "nudge": {"draws": [0]}}, sort_keys=False))
    out = tmp_path / "runs"
    assert main(["run", str(study), "--output-dir", str(out), "--settings", "coarse", "--no-progress"]) == 0
    assert (out / "coarse" / "plain" / "episodes.parquet").is_file() and (out / "coarse" / "nudge0" / "episodes.parquet").is_file()
    assert not (out / "fine").exists()
    assert main(["run", str(study), "--output-dir", str(out), "--settings", "coarse", "--no-progress"]) == 0  # resumed: nothing to play
    assert main(["summarize", str(out), "--summary-to", str(tmp_path / "summary")]) == 0
    table = pd.read_csv(tmp_path / "summary" / "convergence.csv")
    assert list(table["setting"]) == ["coarse"] * 2 and list(table["level"]) == ["all", "low"]
    assert table.iloc[0]["episodes"] == 1 and table.iloc[0]["nudge_change_n"] == 1
    assert "the finest setting fine has no episodes" in (tmp_path / "summary" / "README.md").read_text()


def test_the_power_calculation_reads_the_committed_summaries_and_more_seeds_decide_more():
    from studies.scoop_convergence.power import PAPER_RATIO, chain_counts, decision_probability, power_table

    counts = chain_counts()
    assert set(counts["level"]) == {"brim", "paper levels"} and (counts.groupby("level").size() == 2).all()
    inputs, designs = power_table(counts)
    brim = inputs[inputs["level"] == "brim"].iloc[0]
    assert brim["paired"] == counts[counts["level"] == "brim"]["paired"].sum()
    # a true ratio of 1 is told from 0.6 with certainty at infinite seeds and never with none
    assert decision_probability(1.0, 0.5, 0.4, 0.0, 3, 10**6) == pytest.approx(1.0)
    assert decision_probability(PAPER_RATIO, 0.5, 0.4, 0.0, 3, 1000) > decision_probability(PAPER_RATIO, 0.5, 0.4, 0.0, 3, 50)
    # more chains never need more seeds per chain
    for _, row in designs.iterrows():
        needed = [row[f"seeds_k{k}"] for k in (2, 3, 5, 10)]
        assert all(a >= b for a, b in zip(needed, needed[1:]) if not (pd.isna(a) or pd.isna(b)))
