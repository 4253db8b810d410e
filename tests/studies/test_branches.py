"""Branch studies: the policy's samples from one state, scored within the state (studies/outcome_sensitivity/branches.py)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from grits_lab.errors import InputError
from grits_lab.evaluation.evaluation_run import evaluate
from studies.outcome_sensitivity.__main__ import main as study_main
from studies.outcome_sensitivity.branches import branch_markdown, branch_predictions, branch_runs, outcome_spread, selection
from studies.outcome_sensitivity.hooks import OutcomeHook
from tests.evaluation.eval_helpers import eval_config

SCOOP = {"max_steps": 36, "min_steps": 36}


@pytest.fixture(scope="module")
def study(models, tmp_path_factory) -> dict[str, Path]:
    """Run directories of dp on two episodes: unbranched ("plain"), and draws 0, 1, 2 of plan 1."""
    root = tmp_path_factory.mktemp("branches")
    runs = {}
    for name, hook in {"plain": None, "draw0": OutcomeHook(branch_plan=1), "draw1": OutcomeHook(branch_plan=1, branch_draw=1),
                       "draw2": OutcomeHook(branch_plan=1, branch_draw=2)}.items():
        config = eval_config(models, root / name, methods=["dp"], rollout_chunks=True, trials=2, scoop=SCOOP)
        assert (evaluate(config, progress=False, hook=hook)["error"] == "").all()
        runs[name] = root / name
    return runs


def _episodes(run: Path) -> list[dict[str, np.ndarray]]:
    from grits_lab.data.format import read_episode

    return [read_episode(f)[0] for f in sorted((run / "rollout_chunks" / "dp" / "episodes").glob("*.npz"))]


def test_a_branch_draw_shares_every_step_before_its_plan_and_samples_another_chunk_from_that_state(study, models, tmp_path):
    """Draw 0 is the unbranched episode; draw 1 executes the same first chunk, sees the same cloud at
    the branch plan and executes another sample there. A run directory holds one draw, and only
    diffusion methods draw noise to branch on."""
    records = {name: pd.read_parquet(run / "episodes.parquet") for name, run in study.items()}
    assert set(records["plain"]["scoop_branch_plan"]) == {-1} and set(records["draw1"]["scoop_branch_plan"]) == {1}
    assert set(records["draw0"]["scoop_branch_draw"]) == {0} and set(records["draw1"]["scoop_branch_draw"]) == {1}
    first, branch = slice(0, 12), slice(12, 24)
    for plain, own, other in zip(*(_episodes(study[n]) for n in ("plain", "draw0", "draw1"))):
        np.testing.assert_array_equal(own["trajectory"], plain["trajectory"])
        np.testing.assert_array_equal(other["trajectory"][first], own["trajectory"][first])
        np.testing.assert_array_equal(other["chunk_cloud"][1], own["chunk_cloud"][1])  # one state
        assert np.abs(other["trajectory"][branch, :3] - own["trajectory"][branch, :3]).max() > 1e-3
    resumed = tmp_path / "draw0"
    shutil.copytree(study["draw0"], resumed)
    with pytest.raises(InputError, match="scoop_branch_plan 1, scoop_branch_draw 0, but this run's scoop hook writes"):
        evaluate(eval_config(models, resumed, methods=["dp"], rollout_chunks=True, trials=2, scoop=SCOOP), progress=False,
                 hook=OutcomeHook(branch_plan=1, branch_draw=2))
    with pytest.raises(InputError, match="diffusion-policy methods"):
        evaluate(eval_config(models, tmp_path / "expert", methods=["expert"]), progress=False, hook=OutcomeHook(branch_plan=0))
    assert not (tmp_path / "expert").exists()
    with pytest.raises(InputError, match="needs the plan"):
        OutcomeHook(branch_draw=1)


def test_the_spread_counts_disagreeing_states_and_the_within_state_variance():
    """Two states of two draws: one whose draws disagree (s = 1 of 2: s (K - s) / (K (K - 1)) = 1/2),
    one where both spill (0)."""
    frame = pd.DataFrame({"state": ["a", "a", "b", "b"], "draw": [0, 1, 0, 1], "label": [1, 0, 1, 1]})
    spread = outcome_spread(frame)
    assert (spread["states"], spread["draws"], spread["mixed"], spread["all_spill"]) == (2, 2, 1, 1)
    assert spread["rate"] == pytest.approx(0.75) and spread["within"] == pytest.approx(0.25)
    assert spread["within_share"] == pytest.approx((1 * 1 / 2) / 4 / (0.75 * 0.25))  # sum s (K - s) / K over all draws, over m (1 - m)
    assert spread["left_out"] == 0
    frame.attrs["states_left_out"] = ["c"]  # as branch_predictions names a state some runs lack
    assert outcome_spread(frame)["left_out"] == 1
    picked = selection(frame.assign(branch=frame["draw"], own=frame["draw"] == 0), [], n_resamples=100)
    assert "Left out: 1 states that reached the plan in some runs only" in branch_markdown(outcome_spread(frame), picked, 1, "horizon")


def test_a_guide_that_ranks_the_draws_picks_the_one_that_does_not_spill():
    """Per state the pick is the draw of lowest P(spill): `right` picks the safe draw of state a,
    `wrong` the spilling one; in b every draw spills. own = draw 0, best = the safest draw, random =
    the state's mean (a: 1/2, b: 1)."""
    frame = pd.DataFrame({"state": ["a", "a", "b", "b"], "branch": [0, 1, 0, 1], "own": [True, False, True, False], "label": [1, 0, 1, 1],
                          "p_right": [0.9, 0.1, 0.5, 0.4], "p_wrong": [0.1, 0.9, 0.5, 0.4]})
    table = selection(frame, ["right", "wrong"], n_resamples=200).set_index("choice")
    assert table.loc["own", "rate"] == 1.0 and table.loc["best", "rate"] == 0.5
    assert table.loc["right", "rate"] == 0.5 and table.loc["right", "minus_own"] == -0.5
    assert table.loc["wrong", "rate"] == 1.0 and table.loc["wrong", "minus_own"] == 0.0
    assert table.loc["right", "minus_own_lo"] <= -0.5 <= table.loc["right", "minus_own_hi"]
    assert table.loc["random", "rate"] == 0.75 and list(table.index) == ["own", "best", "random", "right", "wrong"]
    assert table.loc["right", "minus_random"] == -0.25 and table.loc["wrong", "minus_random"] == 0.25
    assert table.loc["right", "minus_random_lo"] <= -0.25 <= table.loc["right", "minus_random_hi"]
    assert pd.isna(table.loc["best", "minus_random"])  # only a model's pick is set against a random one


def test_the_best_of_k_samples_is_set_against_the_best_of_k_replays_of_the_own_sample():
    """Runs: 0 the own sample, 1 another draw, 2 a nudged replay of draw 0, 3 a third draw. k = 2 (two
    replays): samples {0, 1}, replays {0, 2}; run 3 counts in `best` only. State a: a sample avoids the
    spill and the replay does not (-1); b: only run 3 avoids it (0 for both bests, 0 for `best`);
    c: draw 0 is safe (0). Mean gap -1/3."""
    from studies.outcome_sensitivity.branches import samples_and_replays

    frame = pd.DataFrame({"state": np.repeat(["a", "b", "c"], 4), "branch": [0, 1, 2, 3] * 3, "draw": [0, 1, 0, 2] * 3,
                          "offset_m": [0, 0, 0.0005, 0] * 3, "own": [True, False, False, False] * 3,
                          "label": [1, 0, 1, 0, 1, 1, 1, 0, 0, 1, 1, 1]})
    assert samples_and_replays(frame) == ([0, 1], [0, 2])
    table = selection(frame, [], n_resamples=200).set_index("choice")
    assert list(table.index) == ["own", "best", "random", "best_samples", "best_replays"]
    assert table.loc["best", "rate"] == 0.0 and table.loc["own", "rate"] == pytest.approx(2 / 3)
    assert table.loc["best_samples", "rate"] == pytest.approx(1 / 3) and table.loc["best_replays", "rate"] == pytest.approx(2 / 3)
    assert table.loc["best_samples", "minus_replays"] == pytest.approx(-1 / 3) and table.loc["best_samples", "k"] == 2
    assert table.loc["best_samples", "minus_replays_lo"] <= -1 / 3 <= table.loc["best_samples", "minus_replays_hi"]
    text = branch_markdown(outcome_spread(frame), table.reset_index(), 1, "horizon")
    assert "the best of 2 runs of its own sample" in text and "paired by state: -0.333" in text
    reordered = frame.assign(branch=frame["branch"].map({0: 2, 1: 0, 2: 3, 3: 1}))  # given as draw1, draw2, draw0, nudge
    assert samples_and_replays(reordered) == ([2, 0], [2, 3])  # the own run first in both, whatever the order
    with pytest.raises(InputError, match="'best_samples', a row of the selection table"):
        selection(frame.assign(p_best_samples=0.5), ["best_samples"], n_resamples=100)
    draws_only = frame[frame["branch"] != 2]  # no replay: no such rows
    assert samples_and_replays(draws_only) == ([], [])
    assert list(selection(draws_only, [], n_resamples=100)["choice"]) == ["own", "best", "random"]


def test_branch_runs_are_scored_at_their_plan_within_each_state_and_the_cli_writes_the_pick(study, models, tmp_path):
    """Three draws of two episodes: one row per (state, draw), the chunk executed at the branch plan,
    a guide's P(spill) differing across the draws of a state; the CLI writes the comparison with
    the within-state AUROC and the selection table."""
    from grits_lab.cli import main

    runs = [study[f"draw{d}"] for d in (0, 1, 2)]
    checkpoint = Path(models["predictor"])
    frame = branch_predictions({"tiny": checkpoint}, runs, label="chunk")
    assert len(frame) == 6 and frame["state"].nunique() == 2 and sorted(frame["draw"].unique()) == [0, 1, 2]
    assert (frame["chunk"] == 1).all() and (frame["episode"] == frame["state"]).all()
    assert frame.groupby("state")["p_tiny"].nunique().min() > 1  # another trajectory, another score

    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump({"name": "tiny", "output_dir": str(checkpoint.parent.parent),
                                      "model": {"dp3": {"hidden_dims": [16, 32], "out_dim": 16}, "fusion_mlp": [32, 16]},
                                      "data": {"dataset": "unused", "points_per_object": 16}}))
    out = tmp_path / "compared"
    out.mkdir()
    (out / "tiny").symlink_to(checkpoint.parent)  # the trained run, where --output-dir looks for it
    assert study_main(["branches", *map(str, runs), "--predictors", str(config), "--label", "chunk", "--bootstrap", "100",
                 "--output-dir", str(out)]) == 0
    written = out / "comparison_branches_test_plan1_draw0+draw1+draw2_dp_chunk"  # the runs' run_id and names
    markdown = (written / "predictor_comparison.md").read_text()
    assert "AUROC within state" in markdown and "## The draws of one state (plan 1, chunk label)" in markdown
    assert "picked by tiny (lowest P(spill))" in markdown
    picked = pd.read_csv(written / "branch_selection.csv")
    assert list(picked["choice"]) == ["own", "best", "random", "tiny"]
    own = frame[frame["draw"] == 0].sort_values("state")["label"].mean()
    assert picked.set_index("choice").loc["own", "rate"] == pytest.approx(own)


def test_without_a_model_the_spread_reads_the_same_labels_and_the_cli_writes_own_best_and_random(study, models, tmp_path, capsys):
    """No CONFIG: the labels come from the rollout chunks alone, equal to those the model path reads,
    and the CLI writes the spread with the own and best rows only."""
    from grits_lab.cli import main

    runs = [study[f"draw{d}"] for d in (0, 1, 2)]
    alone = branch_predictions({}, runs, label="horizon")
    scored = branch_predictions({"tiny": Path(models["predictor"])}, runs, label="horizon")
    columns = ["state", "branch", "draw", "own", "food", "label"]
    pd.testing.assert_frame_equal(alone[columns], scored[columns], check_dtype=False)
    assert alone.attrs["states_left_out"] == [] and set(alone["offset_draw"]) == {0}
    assert study_main(["branches", *map(str, runs), "--bootstrap", "100", "--output-dir", str(tmp_path)]) == 0
    written = tmp_path / "comparison_branches_test_plan1_draw0+draw1+draw2_dp_horizon"
    assert "## The draws of one state (plan 1, horizon label)" in (written / "branch_spread.md").read_text()
    picked = pd.read_csv(written / "branch_selection.csv").set_index("choice")
    assert list(picked.index) == ["own", "best", "random"]
    by_state = alone.groupby("state")["label"]
    assert picked.loc["best", "rate"] == pytest.approx(by_state.min().mean())
    assert picked.loc["random", "rate"] == pytest.approx(by_state.mean().mean())
    assert picked.loc["own", "rate"] == pytest.approx(alone[alone["own"]].sort_values("state")["label"].mean())
    capsys.readouterr()
    assert main(["compare-predictors", "a.yaml", "--eval", str(runs[0])]) == 2
    assert "--eval is retired; use --held-out" in capsys.readouterr().err


def _with_records(run: Path, where: Path, **columns) -> Path:
    """A copy of a run directory whose records hold other values in `columns`."""
    shutil.copytree(run, where)
    records = pd.read_parquet(where / "episodes.parquet").assign(**columns)
    records.to_parquet(where / "episodes.parquet")
    return where


def _with_config(run: Path, where: Path, section: str, **changes) -> Path:
    """A copy of a run directory whose config.yaml says other settings in `section`."""
    shutil.copytree(run, where)
    config = yaml.safe_load((where / "config.yaml").read_text())
    config[section].update(changes)
    (where / "config.yaml").write_text(yaml.safe_dump(config))
    return where


def test_branch_runs_that_cannot_be_one_study_are_refused_before_any_model_runs(study, tmp_path):
    first = study["draw0"]
    with pytest.raises(InputError, match="at least two runs"):
        branch_runs([first])
    with pytest.raises(InputError, match="listed twice"):
        branch_runs([first, first])
    with pytest.raises(InputError, match="different plans"):
        branch_runs([first, _with_records(study["draw1"], tmp_path / "plan2", scoop_branch_plan=2)])
    with pytest.raises(InputError, match="transfer.enabled"):
        branch_runs([first, _with_config(study["draw1"], tmp_path / "scoop_only", "transfer", enabled=False)])
    with pytest.raises(InputError, match="branch at no plan"):
        branch_runs([first, study["plain"]])
    with pytest.raises(InputError, match="no run is draw 0 without a nudge"):
        branch_runs([study["draw1"], study["draw2"]])
    with pytest.raises(InputError, match="no rollout chunks of method 'grits'"):
        branch_runs([first, study["draw1"]], method="grits")


def test_runs_that_did_not_share_the_state_are_refused_naming_the_episode(study, models, tmp_path):
    """A run whose episode saw another cloud at the branch plan did not branch from the same state."""
    from grits_lab.data.format import read_episode, write_episode

    second = tmp_path / "draw1"
    shutil.copytree(study["draw1"], second)
    dataset = second / "rollout_chunks" / "dp"
    files = sorted((dataset / "episodes").glob("*.npz"))
    arrays, meta = read_episode(files[0])
    arrays["chunk_cloud"] = np.asarray(arrays["chunk_cloud"]) + np.float16(0.01)
    write_episode(dataset, files[0].stem, arrays, meta)
    with pytest.raises(InputError, match=f"episode .*{files[0].stem}.* another cloud at plan 1"):
        branch_predictions({"tiny": Path(models["predictor"])}, [study["draw0"], second], label="chunk")


def test_the_study_commands_refuse_a_hook_they_cannot_run_before_anything_is_written(capsys, tmp_path):
    """`branch` on a config with methods that sample no noise, a nudge draw without a nudge, and the
    retired `evaluate` flags: one line and exit 2, nothing written."""
    from grits_lab.cli import main
    from grits_lab.evaluation.evaluation_config import load_evaluation_config

    out = tmp_path / "never"
    assert study_main(["branch", "experiments/evaluate_quick.yaml", "--plan", "1", "--draw", "1", "--output-dir", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a branch needs diffusion-policy methods" in err[0] and not out.exists()
    assert study_main(["nudge", "experiments/evaluate_quick.yaml", "--offset", "0", "--draw", "3", "--output-dir", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a nudge draw needs a nudge" in err[0] and not out.exists()
    for flag in ("--branch-draw", "--action-offset-draw"):
        assert main(["evaluate", "experiments/evaluate_quick.yaml", flag, "1", "--output-dir", str(out)]) == 2
        assert "is retired; use `python -m studies.outcome_sensitivity" in capsys.readouterr().err and not out.exists()
    study = load_evaluation_config("studies/outcome_sensitivity/configs/dp_branches_brim.yaml")
    assert study.methods == ["dp"] and study.transfer.enabled is False


def test_a_nudged_replay_shares_the_state_and_the_sample_and_moves_only_from_the_branch_plan(study, models, tmp_path, capsys):
    """With a branch plan, `scoop.action_offset` moves the actions from that plan on only: the first
    chunk is draw 0's, the branch chunk is draw 0's sample moved by the offset; the study takes it as
    another run of the same state, and refuses it twice."""
    offset = 0.003
    config = eval_config(models, tmp_path / "nudged", methods=["dp"], rollout_chunks=True, trials=2, scoop=SCOOP)
    records = evaluate(config, progress=False, hook=OutcomeHook(offset=offset, branch_plan=1))
    assert set(records["scoop_action_offset_m"]) == {offset} and set(records["scoop_branch_draw"]) == {0}
    seeds = records.sort_values("trial")["seed"].astype(int)  # episode files sort by trial, as records do
    for own, nudged, seed in zip(_episodes(study["draw0"]), _episodes(tmp_path / "nudged"), seeds):
        np.testing.assert_array_equal(nudged["trajectory"][:12], own["trajectory"][:12])
        np.testing.assert_array_equal(nudged["chunk_cloud"][1], own["chunk_cloud"][1])
        shift = nudged["trajectory"][12:24].astype(np.float64) - own["trajectory"][12:24]  # the same sample, moved
        expected = OutcomeHook(offset=offset).offset_vector(seed)
        np.testing.assert_allclose(shift, np.broadcast_to(expected, shift.shape), atol=1e-6)
    runs = branch_runs([study["draw0"], tmp_path / "nudged", study["draw1"]])
    assert [r.own for r in runs] == [True, False, False] and runs[1].key == (0, offset, 0)
    frame = branch_predictions({"tiny": Path(models["predictor"])}, [study["draw0"], tmp_path / "nudged"], label="chunk")
    assert list(frame.groupby("state")["own"].sum()) == [1, 1]
    with pytest.raises(InputError, match="listed twice"):
        branch_runs([study["draw0"], tmp_path / "nudged", tmp_path / "nudged"])
    # another nudge draw on the run's own config: the records' draw 0 is not resumed as draw 3
    assert study_main(["branch", str(tmp_path / "nudged" / "config.yaml"), "--plan", "1", "--offset", str(offset),
                       "--offset-draw", "3", "--serial"]) == 2
    err = capsys.readouterr().err
    assert "scoop_action_offset_draw 0, scoop_branch_plan 1" in err and "scoop_action_offset_draw 3" in err

    # draws 0 and 1 beside draw 0 and its replay: the best of two samples against the best of two replays
    assert study_main(["branches", str(study["draw0"]), str(tmp_path / "nudged"), str(study["draw1"]),
                 "--bootstrap", "100", "--output-dir", str(tmp_path / "spread")]) == 0
    written = tmp_path / "spread" / "comparison_branches_test_plan1_draw0+nudged+draw1_dp_horizon"
    picked = pd.read_csv(written / "branch_selection.csv").set_index("choice")
    labels = branch_predictions({}, [study["draw0"], tmp_path / "nudged", study["draw1"]], label="horizon")
    best = {name: labels[labels["branch"].isin(among)].groupby("state")["label"].min().mean()
            for name, among in (("best_samples", [0, 2]), ("best_replays", [0, 1]))}
    assert picked.loc["best_samples", "rate"] == pytest.approx(best["best_samples"])
    assert picked.loc["best_replays", "rate"] == pytest.approx(best["best_replays"])
    assert picked.loc["best_samples", "minus_replays"] == pytest.approx(best["best_samples"] - best["best_replays"])
    assert "best of 2 samples minus best of 2 replays" in (written / "branch_spread.md").read_text().lower()


def test_a_second_study_whose_runs_have_the_same_names_does_not_overwrite_the_first_comparison(study, tmp_path, capsys):
    other = tmp_path / "other_study"
    for name in ("draw0", "draw1"):
        shutil.copytree(study[name], other / name)
    first = [str(study["draw0"]), str(study["draw1"])]
    assert study_main(["branches", *first, "--bootstrap", "100", "--output-dir", str(tmp_path / "cmp")]) == 0
    written = tmp_path / "cmp" / "comparison_branches_test_plan1_draw0+draw1_dp_horizon"
    kept = (written / "branch_selection.csv").read_text()
    capsys.readouterr()
    second = [str(other / "draw0"), str(other / "draw1")]
    assert study_main(["branches", *second, "--bootstrap", "100", "--output-dir", str(tmp_path / "cmp")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{written} holds the comparison of the runs {study['draw0'].resolve()}" in err[0], err
    assert (written / "branch_selection.csv").read_text() == kept
    assert study_main(["branches", *first, "--bootstrap", "100", "--output-dir", str(tmp_path / "cmp")]) == 0  # the same runs again
