"""Training on tiny datasets in the real format: overfitting, checkpoints, resume, split, errors, CLI."""

from __future__ import annotations

import json
import re
import shutil

import pandas as pd
from pathlib import Path

import numpy as np
import pytest
import yaml

from grits_lab.cli import main
from grits_lab.config import config_from_dict, config_to_dict
from grits_lab.data.format import list_episode_files, load_index, read_episode
from grits_lab.errors import ConfigError, InputError
from grits_lab.spillage.predictor_checkpoint import load_predictor
from grits_lab.spillage.predictor_config import PredictorConfig
from grits_lab.spillage.chunk_dataset import split_spillage_episodes, split_training_datasets, trajectory_window
from grits_lab.spillage.predictor_training import evaluate_predictor, train_predictor


def _config(tmp_path, dataset, epochs=2, **model):
    return config_from_dict(PredictorConfig, {
        "name": "tiny",
        "output_dir": str(tmp_path / "runs"),
        "model": {"dp3": {"hidden_dims": [32, 64], "out_dim": 32}, **model},
        "data": {"dataset": str(dataset), "val_fraction": 0.25},
        "train": {"epochs": epochs, "batch_size": 8, "lr": 3e-3, "num_threads": 1},
    })


def test_overfits_a_tiny_set(tmp_path, tiny_dataset):
    cfg = _config(tmp_path, tiny_dataset, epochs=60)
    cfg.model.dropout = 0.0
    result = train_predictor(cfg, progress=False)
    history = json.loads((tmp_path / "runs" / "tiny" / "history.json").read_text())
    assert len(history) == 60
    assert history[-1]["train_accuracy"] == 1.0
    assert history[-1]["train_loss"] < 0.1 < history[0]["train_loss"]
    assert result["best_epoch"]["val_loss"] == min(r["val_loss"] for r in history)
    # The same metric logger as the policy's: one row per epoch, and the curves drawn on close.
    log = pd.read_csv(tmp_path / "runs" / "tiny" / "metrics.csv")
    assert list(log["step"]) == list(range(1, 61)) and list(log["val_auroc"]) == [r["val_auroc"] for r in history]
    assert log["lr"].iloc[0] == 3e-3 and (tmp_path / "runs" / "tiny" / "curves.png").stat().st_size > 0


def test_checkpoint_round_trip(tmp_path, tiny_dataset):
    cfg = _config(tmp_path, tiny_dataset, epochs=1)
    train_predictor(cfg, progress=False)
    a = load_predictor(tmp_path / "runs" / "tiny" / "last.pt")
    b = load_predictor(tmp_path / "runs" / "tiny" / "last.pt")
    assert a.config == cfg
    rng = np.random.default_rng(0)
    traj = rng.uniform(-0.05, 0.05, (3, 12, 9)).astype(np.float32) + np.array([0.5, 0, 0.05, 1, 0, 0, 0, 1, 0], np.float32)
    cloud = rng.normal([0.5, 0, 0.05], 0.05, (3, 3, 48, 3)).astype(np.float32)
    np.testing.assert_array_equal(a.predict_world(traj, cloud), b.predict_world(traj, cloud))
    assert not any(p.requires_grad for p in a.model.parameters())
    report = evaluate_predictor(a, tiny_dataset)
    assert report["n"] == 12 * 3 and 0.0 <= report["accuracy"] <= 1.0


def test_resumed_run_equals_uninterrupted_run(tmp_path, tiny_dataset):
    straight = _config(tmp_path / "a", tiny_dataset, epochs=3)
    train_predictor(straight, progress=False)
    interrupted = _config(tmp_path / "b", tiny_dataset, epochs=2)
    train_predictor(interrupted, progress=False)
    interrupted.train.lr = 1e-3  # a changed config is refused ...
    with pytest.raises(ConfigError, match="--restart"):
        train_predictor(interrupted, progress=False)
    # ... but a longer schedule resumes after the last finished epoch
    train_predictor(_config(tmp_path / "b", tiny_dataset, epochs=3), progress=False)
    h_a = json.loads((tmp_path / "a" / "runs" / "tiny" / "history.json").read_text())
    h_b = json.loads((tmp_path / "b" / "runs" / "tiny" / "history.json").read_text())
    assert [r["val_loss"] for r in h_a] == pytest.approx([r["val_loss"] for r in h_b], abs=1e-6)


def test_the_same_training_writes_a_byte_identical_checkpoint_and_keeps_its_timings_beside_it(tmp_path, tiny_dataset):
    # provenance names a checkpoint by its file digest, so the wall-clock seconds stay out of it
    cfg = _config(tmp_path, tiny_dataset, epochs=2)
    run = tmp_path / "runs" / "tiny"
    train_predictor(cfg, progress=False)
    first = {name: (run / name).read_bytes() for name in ("best.pt", "last.pt")}
    train_predictor(cfg, restart=True, progress=False)
    assert {name: (run / name).read_bytes() for name in ("best.pt", "last.pt")} == first
    history = json.loads((run / "history.json").read_text())
    assert all(r["seconds"] > 0 for r in history)
    # a resumed run keeps the finished epochs' timings in history.json
    train_predictor(_config(tmp_path, tiny_dataset, epochs=3), progress=False)
    resumed = json.loads((run / "history.json").read_text())
    assert [r["seconds"] for r in resumed[:2]] == [r["seconds"] for r in history] and resumed[2]["seconds"] > 0


def test_split_is_by_episode_and_can_hold_out_a_shape(tiny_dataset):
    index = load_index(tiny_dataset)
    split = split_spillage_episodes(index, 0.25, seed=0)
    assert not set(split.train) & set(split.val) and len(split.val) == 3
    assert split_spillage_episodes(index, 0.25, seed=0) == split
    held = split_spillage_episodes(index, 0.25, seed=0, holdout_shape="cone")
    shapes = dict(zip(index["file"], index["shape"]))
    assert {shapes[f] for f in held.val} == {"cone"} and "cone" not in {shapes[f] for f in held.train}
    with pytest.raises(InputError, match="torus"):
        split_spillage_episodes(index, 0.25, seed=0, holdout_shape="torus")


def test_short_last_chunk_is_padded_with_the_final_pose():
    traj = np.arange(20 * 9, dtype=np.float32).reshape(20, 9)
    window = trajectory_window(traj, 12, 12)
    assert window.shape == (12, 9)
    np.testing.assert_array_equal(window[:8], traj[12:])
    np.testing.assert_array_equal(window[8:], np.repeat(traj[-1:], 4, 0))


def test_cli_trains_evaluates_and_reports_bad_input_in_one_line(tmp_path, tiny_dataset, capsys):
    cfg_path = tmp_path / "p.yaml"
    cfg_path.write_text(yaml.safe_dump({
        "name": "cli", "output_dir": str(tmp_path / "runs"),
        "model": {"dp3": {"hidden_dims": [16], "out_dim": 16}},
        "train": {"epochs": 1, "batch_size": 16, "num_threads": 1},
    }))
    assert main(["train", "predictor", str(cfg_path), "--no-progress", "--dataset", str(tiny_dataset)]) == 0
    assert main(["train", "predictor", str(cfg_path), "--dataset", str(tiny_dataset), "--held-out", str(tiny_dataset)]) == 0
    assert (tmp_path / "runs" / "cli" / "eval_tiny.json").exists()
    capsys.readouterr()
    bad = tmp_path / "bad.yaml"
    bad.write_text("train:\n  epocs: 3\n")
    assert main(["train", "predictor", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "epocs" in err[0]
    demos = tmp_path / "demos"
    (demos / "episodes").mkdir(parents=True)
    (demos / "dataset.yaml").write_text("kind: demos\n")
    assert main(["train", "predictor", str(cfg_path), "--restart", "--dataset", str(demos)]) == 2
    assert "kind 'spillage'" in capsys.readouterr().err


def test_a_predictor_chunk_length_the_dataset_was_not_collected_with_is_refused_before_training(tmp_path, tiny_dataset):
    dataset = Path(shutil.copytree(tiny_dataset, tmp_path / "d12"))  # collected with chunks of 12
    manifest = yaml.safe_load((dataset / "dataset.yaml").read_text())
    (dataset / "dataset.yaml").write_text(yaml.safe_dump({**manifest, "config": {"n_action_steps": 12}}))
    with pytest.raises(ConfigError, match=r"`model.n_action_steps` is 8, .* collected with n_action_steps 12"):
        train_predictor(_config(tmp_path, dataset, epochs=1, n_action_steps=8), progress=False)
    assert not (tmp_path / "runs").exists()


def _retired(source, key, remedy):
    """The one line that refuses `key`, the chunk length's name before scoop-v4, in `source`."""
    return (rf"^{re.escape(str(source))}: `{re.escape(key)}` is the chunk length's name before scoop-v4, which this code "
            rf"no longer reads \(it reads `n_action_steps`\); {remedy} under the current protocol \(docs/migration.md\)$")


def test_a_dataset_that_calls_the_chunk_length_chunk_len_is_refused_naming_the_file_and_key(tmp_path, tiny_dataset):
    from grits_lab.data.format import rebuild_index, read_episode, write_episode

    # Its manifest's collection config says `chunk_len`, as every dataset collected before scoop-v4 does.
    dataset = Path(shutil.copytree(tiny_dataset, tmp_path / "old"))
    manifest = yaml.safe_load((dataset / "dataset.yaml").read_text())
    (dataset / "dataset.yaml").write_text(yaml.safe_dump({**manifest, "config": {"chunk_len": 12}}))
    with pytest.raises(ConfigError, match=_retired(dataset / "dataset.yaml", "chunk_len", "collect the dataset again")):
        train_predictor(_config(tmp_path, dataset, epochs=1), progress=False)
    assert not (tmp_path / "runs").exists()

    # Episodes whose meta says `chunk_len`, without a manifest to say so first.
    (dataset / "dataset.yaml").unlink()
    for path in sorted((dataset / "episodes").glob("*.npz")):
        arrays, meta = read_episode(path)
        meta["chunk_len"] = meta.pop("n_action_steps", 12)
        write_episode(dataset, meta.pop("episode_id"), arrays, meta)
    rebuild_index(dataset)
    refused = _retired(dataset / "episodes", "chunk_len", "collect the dataset again")
    with pytest.raises(ConfigError, match=refused):
        train_predictor(_config(tmp_path, dataset, epochs=1), progress=False)
    with pytest.raises(ConfigError, match=refused):  # scoring a predictor on it, as compare-predictors does
        evaluate_predictor(load_predictor(_trained(tmp_path, tiny_dataset)), dataset)


def _trained(tmp_path, dataset):
    train_predictor(_config(tmp_path, dataset, epochs=1), progress=False)
    return tmp_path / "runs" / "tiny" / "last.pt"


def test_a_checkpoint_that_calls_the_chunk_length_chunk_len_is_refused_to_load_and_to_resume(tmp_path, tiny_dataset):
    from grits_lab.spillage.predictor_checkpoint import read_checkpoint
    from grits_lab.training.checkpoints import save_checkpoint

    last = _trained(tmp_path, tiny_dataset)
    payload = read_checkpoint(last)
    model = payload["config"]["model"]
    model["chunk_len"] = model.pop("n_action_steps")  # as predictors trained before scoop-v4 store it
    save_checkpoint(last, payload)
    refused = _retired(last, "model.chunk_len", "train the predictor again")
    with pytest.raises(ConfigError, match=refused):
        load_predictor(last)
    with pytest.raises(ConfigError, match=refused):
        train_predictor(_config(tmp_path, tiny_dataset, epochs=2), progress=False)  # resuming it
    train_predictor(_config(tmp_path, tiny_dataset, epochs=2), restart=True, progress=False)  # starting over writes the current name
    assert read_checkpoint(last)["config"]["model"]["n_action_steps"] == 12


def test_a_non_finite_value_in_the_dataset_is_refused_naming_its_file(tmp_path, tiny_dataset):
    from grits_lab.data.format import read_episode, write_episode
    from grits_lab.errors import StorageError

    dataset = Path(shutil.copytree(tiny_dataset, tmp_path / "d"))
    path = sorted((dataset / "episodes").glob("*.npz"))[5]
    arrays, meta = read_episode(path)
    arrays["trajectory"][3, 2] = np.nan
    write_episode(dataset, meta.pop("episode_id"), arrays, meta)
    with pytest.raises(StorageError, match=rf"{path.name}: `trajectory` holds 1 non-finite value"):
        train_predictor(_config(tmp_path, dataset, epochs=1), progress=False)


def test_a_loss_that_turns_non_finite_stops_training_with_one_line(tmp_path, tiny_dataset, monkeypatch, capsys):
    import torch

    real = torch.nn.functional.cross_entropy
    calls = {"n": 0}

    def diverging(*args, **kwargs):
        calls["n"] += 1
        loss = real(*args, **kwargs)
        return loss * float("nan") if calls["n"] == 3 else loss

    monkeypatch.setattr(torch.nn.functional, "cross_entropy", diverging)
    cfg_path = tmp_path / "p.yaml"
    cfg_path.write_text(yaml.safe_dump({
        "name": "nan", "output_dir": str(tmp_path / "runs"),
        "model": {"dp3": {"hidden_dims": [16], "out_dim": 16}},
        "train": {"epochs": 1, "batch_size": 4, "num_threads": 1},
    }))
    assert main(["train", "predictor", str(cfg_path), "--no-progress", "--dataset", str(tiny_dataset)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "training loss became nan at epoch 1" in err[0], err
    assert not (tmp_path / "runs" / "nan" / "last.pt").exists()  # nothing saved from the diverged weights


def test_summaries_print_strict_json_without_bare_nan():
    from grits_lab.io import to_json

    text = to_json({"first_loss": float("nan"), "best": {"val_auroc": np.float32("inf"), "n": 3}})
    assert json.loads(text) == {"first_loss": None, "best": {"val_auroc": None, "n": 3}}
    assert "NaN" not in text and "Infinity" not in text


def test_a_planted_pickle_is_refused_on_resume_and_by_eval_and_never_runs(tmp_path, tiny_dataset, plant_pickle, capsys):
    cfg = _config(tmp_path, tiny_dataset, epochs=1)
    train_predictor(cfg, progress=False)
    last = tmp_path / "runs" / "tiny" / "last.pt"
    marker = plant_pickle(last, last)
    with pytest.raises(InputError, match=f"refused checkpoint {last}"):
        train_predictor(_config(tmp_path, tiny_dataset, epochs=2), progress=False)
    cfg_path = tmp_path / "p.yaml"
    cfg_path.write_text(yaml.safe_dump(config_to_dict(cfg)))
    capsys.readouterr()
    assert main(["train", "predictor", str(cfg_path), "--held-out", str(tiny_dataset), "--checkpoint", str(last)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(last) in err[0] and "refused" in err[0]
    assert not marker.exists()


def test_a_second_trainer_of_one_run_is_refused_naming_the_first(tmp_path, tiny_dataset, hold_directory):
    from grits_lab.errors import StorageError

    run = tmp_path / "runs" / "tiny"
    run.mkdir(parents=True)
    holder = hold_directory(run, "train predictor")
    with pytest.raises(StorageError, match=rf"is being written by `grits-lab train predictor` \(pid {holder.pid} on"):
        train_predictor(_config(tmp_path, tiny_dataset, epochs=1), progress=False)
    assert [p.name for p in run.iterdir()] == [".grits-lab.lock"]


def test_a_predictor_with_label_horizon_trains_and_scores_on_the_horizon_array(tmp_path, tiny_horizon_dataset):
    from grits_lab.data.format import list_episode_files, read_episode
    from grits_lab.spillage.predictor_training import predict_chunks

    cfg = _config(tmp_path, tiny_horizon_dataset, epochs=1)
    cfg.data.label = "horizon"
    train_predictor(cfg, progress=False)
    predictor = load_predictor(tmp_path / "runs" / "tiny" / "last.pt")
    assert predictor.config.data.label == "horizon"
    episodes = {p.name: read_episode(p)[0] for p in list_episode_files(tiny_horizon_dataset)}
    horizon = np.concatenate([episodes[name]["chunk_spilled_horizon"] for name in sorted(episodes)])
    chunk = np.concatenate([episodes[name]["chunk_spilled"] for name in sorted(episodes)])
    assert (horizon != chunk).any()  # the two labels differ on this set, so the test tells them apart
    frame, _ = predict_chunks(predictor, tiny_horizon_dataset)  # default: the label it trained on
    np.testing.assert_array_equal(frame["label"].to_numpy().astype(bool), horizon)
    frame, _ = predict_chunks(predictor, tiny_horizon_dataset, label="chunk")  # either label can be scored
    np.testing.assert_array_equal(frame["label"].to_numpy().astype(bool), chunk)
    report = evaluate_predictor(predictor, tiny_horizon_dataset)
    assert (report["label"], report["trained_on"]) == ("horizon", "horizon")
    history = json.loads((tmp_path / "runs" / "tiny" / "history.json").read_text())
    assert history[0]["train_accuracy"] >= 0  # one epoch ran on the horizon labels


def test_label_errors_name_the_key(tmp_path, tiny_dataset):
    with pytest.raises(ConfigError, match=r"`data.label` must be one of 'chunk', 'horizon'. Got 'future'"):
        config_from_dict(PredictorConfig, {"data": {"label": "future"}})
    cfg = _config(tmp_path, tiny_dataset, epochs=1)
    cfg.data.label = "horizon"  # a dataset made before horizon labels
    with pytest.raises(ConfigError, match=r"`data.label` is horizon, but the spillage dataset .* without chunk_spilled_horizon"):
        train_predictor(cfg, progress=False)
    assert not (tmp_path / "runs").exists()


def test_a_chunk_label_run_keeps_the_resume_fingerprint_of_runs_made_before_the_label_key(tmp_path, tiny_dataset):
    from grits_lab.config import config_fingerprint
    from grits_lab.spillage.predictor_training import _resume_fingerprint

    cfg = _config(tmp_path, tiny_dataset)
    before = config_to_dict(cfg)
    del before["train"]["epochs"], before["data"]["label"], before["train"]["tracking"], before["train"]["class_weight"]  # runs before these keys
    assert _resume_fingerprint(cfg) == config_fingerprint(before)
    cfg.train.tracking.experiment = "elsewhere"  # where the metrics are shown does not stop a resume
    assert _resume_fingerprint(cfg) == config_fingerprint(before)
    cfg.data.label = "horizon"
    assert _resume_fingerprint(cfg) != config_fingerprint(before)


def test_cli_scores_either_label_and_compare_needs_one_when_predictors_differ(tmp_path, tiny_horizon_dataset, capsys):
    paths = []
    for name, label in (("h", "horizon"), ("c", "chunk")):
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump({
            "name": name, "output_dir": str(tmp_path / "runs"), "model": {"dp3": {"hidden_dims": [16], "out_dim": 16}},
            "data": {"dataset": str(tiny_horizon_dataset), "label": label}, "train": {"epochs": 1, "batch_size": 16, "num_threads": 1},
        }))
        assert main(["train", "predictor", str(path), "--no-progress"]) == 0
        paths.append(str(path))
    assert main(["train", "predictor", paths[1], "--held-out", str(tiny_horizon_dataset), "--label", "horizon"]) == 0
    scored = json.loads((tmp_path / "runs" / "c" / "eval_tiny_horizon_horizon.json").read_text())
    assert (scored["label"], scored["trained_on"]) == ("horizon", "chunk")
    capsys.readouterr()
    assert main(["compare-predictors", *paths, "--held-out", str(tiny_horizon_dataset), "--bootstrap", "100"]) == 2
    assert "--label" in capsys.readouterr().err
    assert main(["compare-predictors", *paths, "--held-out", str(tiny_horizon_dataset), "--bootstrap", "100", "--label", "horizon"]) == 0
    table = json.loads((tmp_path / "runs" / "comparison_tiny_horizon_horizon" / "predictor_comparison.json").read_text())
    assert table["label"] == "horizon" and [m["model"] for m in table["models"] if m["kind"] == "model"] == ["h", "c"]


def test_several_datasets_train_together_each_split_as_when_trained_alone(tmp_path, tiny_dataset, tiny_horizon_dataset):
    alone = split_spillage_episodes(load_index(tiny_horizon_dataset), 0.25, seed=0)
    root, both = split_training_datasets([tiny_dataset, tiny_horizon_dataset], 0.25, seed=0)
    assert root == Path(".")
    assert [f for f in both.val if f.startswith(str(tiny_horizon_dataset))] == [str(tiny_horizon_dataset / f) for f in alone.val]
    assert len(both.train) + len(both.val) == len(load_index(tiny_dataset)) + len(load_index(tiny_horizon_dataset))
    with pytest.raises(InputError, match="twice"):
        split_training_datasets([tiny_dataset, tiny_dataset], 0.25, seed=0)

    cfg = _config(tmp_path, tiny_dataset, epochs=1)
    cfg.data.dataset = [str(tiny_dataset), str(tiny_horizon_dataset)]
    train_predictor(cfg, progress=False)
    trained = load_predictor(tmp_path / "runs" / "tiny" / "best.pt")
    assert trained.config.data.dataset == [str(tiny_dataset), str(tiny_horizon_dataset)]
    history = json.loads((tmp_path / "runs" / "tiny" / "history.json").read_text())
    val_chunks = sum(len(read_episode(Path(f), keys=["chunk_start"])[0]["chunk_start"]) for f in both.val)
    assert history[0]["val_n"] == val_chunks > 0  # validated on the union of the datasets' held-out episodes


def test_cli_trains_on_several_datasets_and_refuses_a_dataset_without_the_label(tmp_path, tiny_dataset, tiny_horizon_dataset, capsys):
    cfg_path = tmp_path / "p.yaml"
    cfg_path.write_text(yaml.safe_dump({
        "name": "two", "output_dir": str(tmp_path / "runs"), "data": {"label": "horizon"},
        "model": {"dp3": {"hidden_dims": [16], "out_dim": 16}},
        "train": {"epochs": 1, "batch_size": 16, "num_threads": 1},
    }))
    # the first dataset has no horizon labels: refused, naming it, before any epoch
    assert main(["train", "predictor", str(cfg_path), "--no-progress", "--dataset", str(tiny_dataset), str(tiny_horizon_dataset)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(tiny_dataset) in err[0] and not (tmp_path / "runs" / "two" / "last.pt").exists()
    second = tmp_path / "second"
    shutil.copytree(tiny_horizon_dataset, second)
    assert main(["train", "predictor", str(cfg_path), "--no-progress", "--dataset", str(tiny_horizon_dataset), str(second)]) == 0
    stored = yaml.safe_load((tmp_path / "runs" / "two" / "config.yaml").read_text())
    assert stored["data"]["dataset"] == [str(tiny_horizon_dataset), str(second)]


def test_cli_refuses_unusable_dataset_paths_in_one_line_before_any_epoch(tmp_path, tiny_dataset, capsys):
    cfg_path = tmp_path / "p.yaml"
    cfg_path.write_text(yaml.safe_dump({
        "name": "bad", "output_dir": str(tmp_path / "runs"), "model": {"dp3": {"hidden_dims": [16], "out_dim": 16}},
        "train": {"epochs": 1, "batch_size": 16, "num_threads": 1},
    }))
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    alias = tmp_path / "alias"
    alias.symlink_to(tiny_dataset)
    cases = {
        "": "`data.dataset` must be",                                  # the flag is checked as the config is
        "x" * 300: "no spillage dataset at",                            # a name the file system refuses
        str(loop): "no spillage dataset at",                            # a link to itself
        str(alias): f"lists {tiny_dataset} twice (again as {alias})",  # one dataset under two names
    }
    for second, expected in cases.items():
        assert main(["train", "predictor", str(cfg_path), "--no-progress", "--dataset", str(tiny_dataset), second]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and expected in err[0], (second[:20], err)
    assert not (tmp_path / "runs").exists()


def test_balanced_class_weights_give_each_class_half_the_loss_and_need_both_classes():
    import torch

    from grits_lab.spillage.predictor_training import class_weights

    labels = np.array([0] * 9 + [1])
    weight = class_weights(labels, "balanced")
    assert torch.allclose(weight, torch.tensor([10 / 18, 10 / 2]))
    assert float(weight[0] * 9) == pytest.approx(float(weight[1] * 1))  # each class carries half
    assert class_weights(labels, "none") is None
    with pytest.raises(InputError, match="train.class_weight: balanced needs both classes"):
        class_weights(np.zeros(5), "balanced")


def test_balanced_class_weights_lift_p_spill_towards_an_even_prior_on_a_set_where_few_spill(tmp_path):
    """Few spilling chunks: with balanced weights each class carries half the loss, so the trained
    P(spill) sits nearer a 50 % prior than the unweighted run's, which follows the set's share of
    spills; both rank the spilling chunks first, and the history logs the positives and the spread."""
    from tests.spillage.conftest import write_tiny_spillage_dataset

    dataset = write_tiny_spillage_dataset(tmp_path / "rare", n_episodes=16, n_chunks=4, seed=3, spill_below=0.04)
    labels = np.concatenate([read_episode(p)[0]["chunk_spilled"] for p in list_episode_files(dataset)])
    assert 0 < labels.mean() < 0.25
    scores = {}
    for mode in ("none", "balanced"):
        cfg = _config(tmp_path / mode, dataset, epochs=25)
        cfg.train.class_weight = mode
        cfg.model.dropout = 0.0
        result = train_predictor(cfg, progress=False)
        scores[mode] = evaluate_predictor(load_predictor(result["best_checkpoint"]), dataset)
        last = json.loads((tmp_path / mode / "runs" / "tiny" / "history.json").read_text())[-1]
        assert last["train_positives"] == int(round(last["train_n"] * last["train_spill_rate"])) and last["train_p_spill_std"] > 0
    assert scores["balanced"]["mean_p_spill"] > scores["none"]["mean_p_spill"] + 0.05
    assert scores["balanced"]["auroc"] > 0.8 and scores["balanced"]["positives"] == int(labels.sum())


def test_the_weighted_loss_is_the_weighted_mean_cross_entropy(tiny_dataset):
    import torch

    from grits_lab.spillage.chunk_dataset import CLOUD_KEYS, SpillageChunkDataset, fit_normalizers
    from grits_lab.spillage.model import SpillagePredictor
    from grits_lab.spillage.predictor_training import predict

    cfg = config_from_dict(PredictorConfig, {"model": {"dp3": {"hidden_dims": [16], "out_dim": 8}}})
    files = sorted(load_index(tiny_dataset)["file"])
    action_norm, cloud_norm = fit_normalizers(tiny_dataset, files, CLOUD_KEYS["composite"], 0.1)
    data = SpillageChunkDataset(tiny_dataset, files, cloud_key=CLOUD_KEYS["composite"], n_action_steps=12, action_normalizer=action_norm,
                                cloud_normalizer=cloud_norm, points_per_object=32, shuffle=False, seed=0, cache=False)
    torch.manual_seed(0)
    model = SpillagePredictor(cfg.model)
    weight = torch.tensor([0.25, 3.0])
    p, y, plain = predict(model, data)
    _, _, weighted = predict(model, data, weight=weight)
    ce = -np.log(np.where(y == 1, p, 1 - p))
    w = np.where(y == 1, 3.0, 0.25)
    assert plain == pytest.approx(ce.mean(), rel=1e-4) and weighted == pytest.approx((w * ce).sum() / w.sum(), rel=1e-4)


def test_runs_without_class_weights_keep_their_resume_fingerprint(tmp_path, tiny_dataset):
    from grits_lab.config import config_fingerprint
    from grits_lab.spillage.predictor_training import _resume_fingerprint

    cfg = _config(tmp_path, tiny_dataset)
    before = config_to_dict(cfg)
    del before["train"]["epochs"], before["data"]["label"], before["train"]["class_weight"], before["train"]["tracking"]
    assert _resume_fingerprint(cfg) == config_fingerprint(before)
    cfg.train.class_weight = "balanced"
    assert _resume_fingerprint(cfg) != config_fingerprint(before)
