"""Held-out comparison of predictors: paired episode bootstrap, table values, the CLI end to end."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest
import yaml

from grits_lab.cli import main
from grits_lab.spillage.compare import compare_predictions
from grits_lab.spillage.classifier_metrics import auroc, auroc_within, classification_report, paired_bootstrap


def _predictions(n_episodes=40, chunks=6, seed=0):
    rng = np.random.default_rng(seed)
    episode = np.repeat([f"ep_{e:03d}" for e in range(n_episodes)], chunks)
    label = rng.integers(0, 2, len(episode))
    good = np.clip(label * 0.6 + rng.uniform(0, 0.4, len(label)), 0, 1)  # separates the classes perfectly
    noise = rng.uniform(0, 1, len(label))  # knows nothing
    return pd.DataFrame({"episode": episode, "chunk": np.tile(np.arange(chunks), n_episodes), "label": label, "p_good": good, "p_noise": noise})


def test_identical_models_differ_by_exactly_zero_in_every_resample():
    frame = _predictions()
    p = frame["p_noise"].to_numpy()
    boot = paired_bootstrap({"a": p, "b": p.copy()}, frame["label"], frame["episode"], n_resamples=200)
    np.testing.assert_array_equal(boot["auroc"]["a"], boot["auroc"]["b"])
    assert boot["auroc"]["a"].std() > 0  # the resamples do differ


def test_resamples_draw_whole_episodes():
    # right on every chunk of even episodes, wrong on every chunk of odd ones: a resample of whole
    # episodes scores a multiple of 1/10, one of single chunks would mostly not
    episodes = np.repeat(np.arange(10), 5)
    labels = np.ones(50, dtype=int)
    p = (episodes % 2 == 0).astype(float)
    acc = paired_bootstrap({"m": p}, labels, episodes, n_resamples=300, metrics=("accuracy",))["accuracy"]["m"]
    np.testing.assert_allclose(acc * 10, np.round(acc * 10), atol=1e-9)
    assert len(np.unique(acc)) > 3


def test_table_holds_the_point_metrics_and_a_significant_paired_difference():
    frame = _predictions()
    c = compare_predictions(frame, ["good", "noise"], n_resamples=500)
    rows = c.table.set_index("model")
    y = frame["label"].to_numpy()
    assert rows.loc["good", "auroc"] == 1.0 == auroc(frame["p_good"], y)
    assert rows.loc["noise", "ece"] == pytest.approx(classification_report(frame["p_noise"], y)["ece"])
    assert rows.loc["noise", "good_minus_auroc"] == pytest.approx(1.0 - auroc(frame["p_noise"], y))
    assert rows.loc["noise", "good_minus_auroc_lo"] > 0.3 and rows.loc["noise", "good_minus_auroc_p"] == 0.0
    assert rows.loc["noise", "auroc_lo"] < rows.loc["noise", "auroc"] < rows.loc["noise", "auroc_hi"]


def _two_foods():
    # food a spills in 3 of 4 chunks, food b in 1 of 4
    food = np.array(["a"] * 4 + ["b"] * 4)
    label = np.array([1, 1, 1, 0, 1, 0, 0, 0])
    return food, label


def test_within_food_auroc_gives_nothing_for_knowing_which_food_spills_more():
    food, label = _two_foods()
    identity = np.where(food == "a", 0.75, 0.25)  # each food's spill rate, the same for all its chunks
    assert auroc(identity, label) == pytest.approx(0.75) and auroc_within(identity, label, food) == 0.5
    # ranks every chunk of a food right, with the foods' levels the wrong way round: pooled AUROC
    # suffers (chunks of b outrank a's spills), within food it is perfect
    ranked = np.array([0.1, 0.1, 0.1, 0.0, 0.9, 0.8, 0.8, 0.8])
    assert auroc(ranked, label) < 0.7 and auroc_within(ranked, label, food) == 1.0
    # the pairs of each food weigh by their count: a holds 3 pairs, b 3; a ranked right, b backwards
    mixed = np.array([0.9, 0.9, 0.9, 0.1, 0.1, 0.9, 0.9, 0.9])
    assert auroc_within(mixed, label, food) == pytest.approx(0.5)
    assert np.isnan(auroc_within(identity, np.zeros(8), food))  # no food holds both classes


def test_the_comparison_scores_within_food_when_the_chunks_name_their_food():
    frame = _predictions()
    frame["food"] = np.where(frame["episode"].str[-1].astype(int) % 2 == 0, "a", "b")
    frame["p_food"] = np.where(frame["food"] == "a", 0.6, 0.4) + 0.0 * frame["label"]  # knows only the food
    c = compare_predictions(frame, ["good", "food"], n_resamples=300)
    rows = c.table.set_index("model")
    assert rows.loc["good", "auroc_within"] == 1.0 and rows.loc["food", "auroc_within"] == 0.5
    assert rows.loc["food", "good_minus_auroc_within"] == pytest.approx(0.5) and rows.loc["food", "good_minus_auroc_within_lo"] > 0.3
    from grits_lab.spillage.compare import comparison_markdown
    text = comparison_markdown(c, "d")
    assert "AUROC within food [95 %]" in text and "| 1.000 [1.000, 1.000] |" in text
    # without a food column, the table holds no within-food AUROC
    assert "auroc_within" not in compare_predictions(_predictions(), ["good", "noise"], n_resamples=50).table.columns


def _position_matters(n_episodes=30, chunks=5, seed=1):
    # two foods; a chunk spills under the horizon label when food will still spill after it: the
    # first chunks of an episode spill more often, food a more often than food b, and among the
    # chunks of one food at one position, those whose `signal` is high spill
    rng = np.random.default_rng(seed)
    episode = np.repeat([f"ep_{e:03d}" for e in range(n_episodes)], chunks)
    chunk = np.tile(np.arange(chunks), n_episodes)
    signal = rng.uniform(0, 1, len(chunk))
    food = np.where(np.arange(len(chunk)) // chunks % 2 == 0, "a", "b")
    label = (signal > 0.2 + 0.15 * chunk + 0.25 * (food == "b")).astype(int)
    return pd.DataFrame({"episode": episode, "chunk": chunk, "food": food, "label": label, "p_signal": signal,
                         "p_position": 1.0 / (1.0 + chunk) + 0.0 * signal, "p_food": np.where(food == "a", 0.7, 0.3)})


def test_the_chunk_position_baseline_ranks_by_position_only_and_scores_half_within_a_position():
    frame = _position_matters()
    y = frame["label"].to_numpy()
    c = compare_predictions(frame, ["signal", "position", "food"], n_resamples=200, label="horizon")
    rows = c.table.set_index("model")
    assert rows.loc["chunk_position", "kind"] == "baseline" and rows.loc["signal", "kind"] == "model"
    # the baseline's rank is the position's: the same AUROC as a model that knows only the position
    assert rows.loc["chunk_position", "auroc"] == pytest.approx(auroc(1.0 / (1.0 + frame["chunk"]), y))
    assert rows.loc["chunk_position", "auroc"] > 0.6
    assert rows.loc["chunk_position", "auroc"] == pytest.approx(rows.loc["position", "auroc"])
    assert np.isnan(rows.loc["chunk_position", "accuracy"]) and np.isnan(rows.loc["chunk_position", "ece"])
    # within food and position, the position earns nothing, nor the food, and the signal everything
    assert rows.loc["chunk_position", "auroc_within_position"] == 0.5 == rows.loc["position", "auroc_within_position"]
    assert rows.loc["food", "auroc"] > 0.6 and rows.loc["food", "auroc_within_position"] == 0.5
    # how much of a model's score is the position: -1 for the position itself, nothing for the signal
    # or the food (constant within a food); a baseline is not scored
    assert rows.loc["position", "spearman_position"] == pytest.approx(-1.0)
    assert abs(rows.loc["signal", "spearman_position"]) < 0.2 and np.isnan(rows.loc["food", "spearman_position"])
    assert np.isnan(rows.loc["chunk_position", "spearman_position"])
    assert rows.loc["signal", "auroc_within_position"] == 1.0
    assert rows.loc["chunk_position", "signal_minus_auroc_within_position_lo"] > 0.3
    from grits_lab.spillage.compare import comparison_markdown
    text = comparison_markdown(c, "d")
    assert "| chunk_position (baseline) |" in text and "AUROC within food and position [95 %]" in text
    baseline_row = next(line for line in text.splitlines() if line.startswith("| chunk_position"))
    assert baseline_row.count("—") == 4 and "0.500 (by construction)" in baseline_row  # no accuracy, ECE, Spearman, accuracy difference
    assert "chunk_position" not in compare_predictions(frame, ["signal"], n_resamples=50, label="horizon", baselines=False).table["model"].tolist()
    assert "chunk_position" not in compare_predictions(frame, ["signal"], n_resamples=50, label="chunk").table["model"].tolist()
    # chunks of one food: stratified by the position alone
    one = compare_predictions(frame[frame["food"] == "a"], ["signal", "position"], n_resamples=50, label="horizon").table.set_index("model")
    assert "auroc_within" not in one.columns and one.loc["position", "auroc_within_position"] == 0.5
    assert one.loc["signal", "auroc_within_position"] == 1.0
    header = comparison_markdown(compare_predictions(frame[frame["food"] == "a"], ["signal"], n_resamples=50, label="horizon"), "d")
    assert "| AUROC within position [95 %] |" in header and "within food" not in header


def test_the_roc_curve_steps_over_ties_and_its_area_is_the_auroc():
    from grits_lab.spillage.compare import roc_points

    frame = _position_matters()
    y = frame["label"].to_numpy()
    for scores in (1.0 / (1.0 + frame["chunk"].to_numpy()), frame["p_signal"].to_numpy(), frame["p_food"].to_numpy()):
        fpr, tpr = roc_points(scores, y)
        assert (fpr[0], tpr[0], fpr[-1], tpr[-1]) == (0.0, 0.0, 1.0, 1.0)
        assert len(fpr) == len(np.unique(scores)) + 1
        assert np.trapezoid(tpr, fpr) == pytest.approx(auroc(scores, y))


def test_paired_bootstrap_takes_strata_per_stratified_metric():
    frame = _position_matters()
    food, position = frame["food"].to_numpy(), (frame["food"] + "#" + frame["chunk"].astype(str)).to_numpy()
    boot = paired_bootstrap({"p": frame["p_position"].to_numpy()}, frame["label"], frame["episode"], n_resamples=50,
                            metrics=("auroc_within", "auroc_within_position"),
                            strata={"auroc_within": food, "auroc_within_position": position})
    np.testing.assert_array_equal(boot["auroc_within_position"]["p"], 0.5)
    assert boot["auroc_within"]["p"].mean() > 0.6
    with pytest.raises(ValueError, match="auroc_within_position needs one stratum per label"):
        paired_bootstrap({"p": frame["p_position"].to_numpy()}, frame["label"], frame["episode"], n_resamples=5,
                         metrics=("auroc_within_position",), strata=food)


def test_cli_compares_trained_predictors_and_refuses_an_untrained_one(tmp_path, tiny_dataset, capsys):
    paths = []
    for name, inputs in (("full", "trajectory_and_cloud"), ("traj", "trajectory")):
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump({
            "name": name, "output_dir": str(tmp_path / "runs"),
            "model": {"inputs": inputs, "dp3": {"hidden_dims": [16], "out_dim": 16}},
            "data": {"dataset": str(tiny_dataset)}, "train": {"epochs": 1, "batch_size": 16, "num_threads": 1},
        }))
        paths.append(str(path))
    assert main(["train", "predictor", paths[0], "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["compare-predictors", *paths, "--held-out", str(tiny_dataset)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "traj.yaml" in err[0] and "train it first" in err[0]
    assert main(["train", "predictor", paths[1], "--no-progress"]) == 0
    out = tmp_path / "runs" / f"comparison_{tiny_dataset.name}"  # under the configs' output_dir
    assert main(["compare-predictors", *paths, "--held-out", str(tiny_dataset), "--output-dir", str(tmp_path / "runs"),
                 "--bootstrap", "200"]) == 0
    summary = json.loads((out / "predictor_comparison.json").read_text())
    # scored by the chunk label: no chunk-position baseline (it ranks by where horizon-label spills fall)
    assert [(m["model"], m["kind"]) for m in summary["models"]] == [("full", "model"), ("traj", "model")]
    assert summary["reference"] == "full"
    predictions = pd.read_parquet(out / "predictions.parquet")
    assert list(predictions.columns) == ["episode", "chunk", "shape", "label", "p_full", "p_traj"]
    assert len(predictions) == 12 * 3 and predictions.groupby("episode")["chunk"].max().eq(2).all()
    assert (out / "predictor_comparison.png").stat().st_size > 10_000
    assert "full − AUROC" in (out / "predictor_comparison.md").read_text()
    # Several held-out sets scored as one: each set's chunks as scored alone, its episodes distinct units.
    second = tmp_path / "second"
    shutil.copytree(tiny_dataset, second)
    assert main(["compare-predictors", *paths, "--held-out", str(tiny_dataset), str(second), "--output-dir", str(tmp_path / "runs"),
                 "--bootstrap", "200"]) == 0
    both = pd.read_parquet(tmp_path / "runs" / f"comparison_{tiny_dataset.name}+second" / "predictions.parquet")
    assert len(both) == 2 * len(predictions) and both["episode"].nunique() == 2 * predictions["episode"].nunique()
    for d in (tiny_dataset, second):
        part = both[both["episode"].str.startswith(f"{d}/")]
        np.testing.assert_allclose(part["p_full"].to_numpy(), predictions["p_full"].to_numpy())
    capsys.readouterr()
    assert main(["compare-predictors", *paths, "--held-out", str(tiny_dataset), str(tiny_dataset) + "/"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--held-out lists" in err[0] and "twice" in err[0]
