"""Whole-task evaluation episodes in the real sim with tiny trained models: determinism, rho = 0, records, resume."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from tests.evaluation.eval_helpers import N_POINTS, eval_config
from grits_lab.errors import ConfigError
from grits_lab.evaluation.controllers import ObsHistory
from grits_lab.evaluation.methods import METHODS
from grits_lab.evaluation.evaluation_run import evaluate, evaluate_guidance
from grits_lab.records import RECORD_COLUMNS
from grits_lab.runners import SerialExecutor

# Columns that legitimately differ between two runs of the same episode (clock, method identity).
VOLATILE = {"method", "rho", "s", "wall_time_s", "scoop_time_s", "transfer_time_s", "plan_time_mean_s", "plan_time_max_s",
            "checkpoint_predictor", "checkpoint_predictor_raw", "checkpoint_predictor_pointnet2", "checkpoint_predictor_horizon", "run_id", "guidance_step"}


def outcome(row: pd.Series) -> dict:
    return {k: v for k, v in row.items() if k not in VOLATILE and v is not None and not (isinstance(v, float) and math.isnan(v))}


@pytest.fixture(scope="module")
def all_methods(models, tmp_path_factory):
    config = eval_config(models, tmp_path_factory.mktemp("all"), methods=list(METHODS))
    return evaluate(config, progress=False)


def test_every_method_gives_a_complete_record(all_methods):
    assert sorted(all_methods["method"]) == sorted(METHODS)
    missing = [c for c in RECORD_COLUMNS if c not in all_methods.columns]
    assert not missing
    assert (all_methods["error"] == "").all(), all_methods[["method", "error"]]
    assert all_methods["seed"].nunique() == 1  # every method saw the same episode
    for column in ("task_success", "spillage", "scoop_failure", "scoop_success", "spilled_before_scoop"):
        assert all_methods[column].map(type).eq(bool).all(), column
    assert (all_methods["scoop_failure"] == ~all_methods["scoop_success"]).all()
    guided = all_methods.set_index("method")
    assert guided.loc["grits", "rho"] == 2.5 and guided.loc["grits", "s"] == 30
    assert np.isnan(guided.loc["dp", "rho"]) and guided.loc["dp", "s"] == -1
    # Guidance ran, on the last 6 of 16 DDIM steps per plan, and moved the trajectory.
    assert guided.loc["grits", "guided_steps"] == 6 * guided.loc["grits", "n_plans"]
    assert guided.loc["grits", "guidance_displacement"] > 0
    assert guided.loc["dp", "guided_steps"] == 0
    assert guided.loc["dp_post", "guided_steps"] == 6 * guided.loc["dp_post", "n_plans"]
    assert len(guided.loc["grits", "checkpoint_policy"]) == 16 and len(guided.loc["grits", "checkpoint_predictor"]) == 16
    # Per plan: P(spill) of the unguided sample from the same noise and of the executed one, the
    # gradient norm and how far the executed chunk moved; the rho definition used is recorded.
    for method in ("grits", "dp_post"):
        row = guided.loc[method]
        n = row["n_plans"]
        assert len(row["plan_p_spill_unguided"]) == len(row["plan_p_spill_guided"]) == len(row["plan_displacement_mm"]) == n
        assert all(0 <= p <= 1 for p in row["plan_p_spill_guided"]) and min(row["plan_displacement_mm"]) >= 0
    assert guided.loc["grits", "guidance_step"] == "gradient" and guided.loc["dp", "guidance_step"] == ""
    # grits_horizon is GRITS guided by the predictor under its own key, recorded under that key
    assert guided.loc["grits_horizon", "guided_steps"] == 6 * guided.loc["grits_horizon", "n_plans"]
    assert guided.loc["grits_horizon", "checkpoint_predictor_horizon"] == guided.loc["grits", "checkpoint_predictor"]


def test_rho_zero_grits_is_dp_for_the_whole_episode(models, tmp_path, all_methods):
    config = eval_config(models, tmp_path, methods=["grits"], guidance={"rho": 0.0, "s": 30})
    grits0 = evaluate(config, progress=False).iloc[0]
    dp = all_methods.set_index("method").loc["dp"].copy()
    dp["method"] = "dp"
    assert grits0["guided_steps"] == 0
    assert outcome(grits0) == outcome(dp)


def test_same_seed_gives_the_same_episode(models, tmp_path, all_methods):
    again = evaluate(eval_config(models, tmp_path, methods=["dp", "scone"]), progress=False).set_index("method")
    first = all_methods.set_index("method")
    for method in ("dp", "scone"):
        assert outcome(again.loc[method]) == outcome(first.loc[method])


class CountingExecutor(SerialExecutor):
    def __init__(self):
        super().__init__()
        self.submitted = []

    def submit(self, spec):
        self.submitted.append(spec.episode_id)
        super().submit(spec)


def test_resume_skips_finished_episodes_and_gives_the_same_table(models, tmp_path):
    config = eval_config(models, tmp_path, methods=["rule_based"], trials=2, levels=["low"])
    full = evaluate(config, progress=False)
    assert len(full) == 2
    path = tmp_path / "episodes.parquet"
    pd.read_parquet(path).iloc[:1].to_parquet(path, index=False)  # as if interrupted after one episode
    executor = CountingExecutor()
    resumed = evaluate(config, progress=False, executor=executor)
    assert executor.submitted == ["rule_based-chocolate_balls-low-1"]
    again = CountingExecutor()
    evaluate(config, progress=False, executor=again)
    assert again.submitted == []
    keep = [c for c in full.columns if c not in VOLATILE]
    pd.testing.assert_frame_equal(resumed[keep], full[keep])
    assert (tmp_path / "config.yaml").is_file() and (tmp_path / "provenance.json").is_file()


def test_sweep_entry_point_evaluates_the_given_episodes_with_the_given_guidance(models, tmp_path):
    from grits_lab.evaluation.evaluation_run import EpisodeKey

    config = eval_config(models, tmp_path / "run")
    keys = [EpisodeKey("chocolate_balls", "low", 0, 11, "train")]
    records = evaluate_guidance(config, keys, rho=1.0, s=12, method="grits", run_id="trial-7")
    assert not (tmp_path / "run").exists()  # the sweep stores the records itself
    row = records.iloc[0]
    assert (row["seed"], row["rho"], row["s"], row["run_id"], row["method"]) == (11, 1.0, 12, "trial-7", "grits")
    assert row["guided_steps"] == 3 * row["n_plans"]  # t = 0, 6, 12 are guided with s = 12


def test_unknown_method_is_one_clear_error(models, tmp_path):
    with pytest.raises(ConfigError, match="methods"):
        eval_config(models, tmp_path, methods=["grits", "magic"])


def test_rule_based_scoops_and_transfers_a_training_food(models, tmp_path):
    config = eval_config(models, tmp_path, methods=["rule_based"], levels=["high"], scoop={"max_steps": 120})
    row = evaluate(config, progress=False).iloc[0]
    assert row["split"] == "train"
    assert row["scoop_success"] and row["scooped"] >= 1
    assert row["transferred"] >= 1 and row["target_locate_error_m"] < 0.02
    assert row["task_success"] == (row["spilled_total"] == 0 and row["transferred"] >= 1)
    # The scripted transfer from the rule-based scoop's end stays within reach, without a posture flip (0.6-1.7 rad).
    assert row["transfer_ik_failures"] == 0 and 0 < row["transfer_max_joint_step_rad"] < 0.5


def test_cli_override_file_sets_any_key_and_an_unknown_key_is_one_error(models, tmp_path, capsys):
    import yaml

    from grits_lab.cli import main
    from grits_lab.config import config_to_dict

    base = tmp_path / "evaluate.yaml"
    base.write_text(yaml.safe_dump(config_to_dict(eval_config(models, tmp_path / "base", methods=["dp", "bc"], trials=3))))
    override = tmp_path / "override.yaml"
    override.write_text(yaml.safe_dump({"methods": ["rule_based"], "trials": 1, "output_dir": str(tmp_path / "run")}))
    assert main(["evaluate", str(base), "--override", str(override), "--serial", "--no-progress"]) == 0
    records = pd.read_parquet(tmp_path / "run" / "episodes.parquet")
    assert list(records["method"]) == ["rule_based"]
    # repeated, the files merge in order, mappings key by key: the second keeps the first's scoop keys
    settle = tmp_path / "settle.yaml"
    settle.write_text(yaml.safe_dump({"scoop": {"settle_steps": 3}, "output_dir": str(tmp_path / "merged")}))
    again = tmp_path / "again.yaml"
    again.write_text(yaml.safe_dump({"scoop": {"min_steps": 12}}))
    assert main(["evaluate", str(base), "--override", str(override), "--override", str(settle), "--override", str(again),
                 "--serial", "--no-progress"]) == 0
    merged = pd.read_parquet(tmp_path / "merged" / "episodes.parquet")
    written = yaml.safe_load((tmp_path / "merged" / "config.yaml").read_text())
    assert list(merged["method"]) == ["rule_based"] and (written["scoop"]["settle_steps"], written["scoop"]["min_steps"]) == (3, 12)
    capsys.readouterr()
    override.write_text("trails: 2\n")
    assert main(["evaluate", str(base), "--override", str(override), "--serial"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "trails" in err[0] and f"merged with --override {override}" in err[0]  # names the file that set it


def test_history_gives_the_commanded_actions_and_the_resting_pose_before_the_first():
    history = ObsHistory()
    rest = np.arange(9, dtype=np.float32)
    history.append({"ee_pose": rest})
    np.testing.assert_array_equal(history.past_actions(2), np.stack([rest, rest]))
    command = rest + 1
    history.append({"ee_pose": rest + 0.5}, command)  # the arm lags its command: the command is what was asked
    np.testing.assert_array_equal(history.past_actions(2), np.stack([rest, command]))
    assert history.past_actions(0).shape == (0, 9)


def test_rollout_chunks_are_a_dataset_the_predictor_scores(models, tmp_path):
    """Each DP episode's scoop, cut into the chunks it executed, labelled by the simulation."""
    from pathlib import Path

    from grits_lab.data.format import load_index, read_episode
    from grits_lab.spillage.compare import predict_all

    config = eval_config(models, tmp_path, methods=["dp"], rollout_chunks=True)
    records = evaluate(config, progress=False)
    assert "_chunks" not in records.columns
    dataset = tmp_path / "rollout_chunks" / "dp"
    index = load_index(dataset)
    assert len(index) == 1 and index["n_action_steps"].iloc[0] == 12
    from grits_lab.data.info import dataset_summary
    from grits_lab.versions import PROTOCOL
    assert dataset_summary(dataset)["protocol"] == PROTOCOL  # the labels are the physics of the protocol it ran under
    arrays, meta = read_episode(dataset / index["file"].iloc[0])
    c = len(arrays["chunk_start"])
    assert c >= 1 and arrays["chunk_cloud"].shape[:3] == (c, 3, N_POINTS)
    assert np.all(arrays["chunk_start"] + 12 <= len(arrays["trajectory"]))
    # The label of a chunk is what the simulation did while it ran.
    spilled = arrays["spilled_over_time"]
    for start, label in zip(arrays["chunk_start"], arrays["chunk_spilled"]):
        before = spilled[start - 1] if start > 0 else 0
        assert bool(label) == bool(spilled[start + 11] > before)
    assert meta["label"] == int(arrays["chunk_spilled"].any()) and meta["spilled"] == records.iloc[0]["spilled"]
    predictions = predict_all({"full": Path(models["predictor"])}, dataset)
    assert len(predictions) == c and predictions["p_full"].between(0, 1).all()
    # The horizon label sees the whole task: the count through the transfer and pour, from each chunk's start.
    until = arrays["spilled_until_delivery"]
    assert len(until) > len(arrays["trajectory"]) and until[-1] == records.iloc[0]["spilled_total"]
    assert np.all(arrays["chunk_spilled_horizon"] >= arrays["chunk_spilled"])
    assert meta["label_horizon"] == int(arrays["chunk_spilled_horizon"].any())
    horizon = predict_all({"full": Path(models["predictor"])}, dataset, label="horizon")
    np.testing.assert_array_equal(horizon["label"].to_numpy().astype(bool), arrays["chunk_spilled_horizon"])


def test_the_policy_holds_when_its_own_proposal_holds_whatever_guidance_adds():
    from grits_lab.evaluation.controllers import Chunk, is_still

    pose = np.array([0.5, 0.0, 0.2, 1, 0, 0, 0, 1, 0], dtype=np.float32)
    holding = np.repeat(pose[None], 12, 0)
    nudged = holding.copy()
    nudged[:, 0] += 0.01  # guidance moved the chunk 1 cm
    assert not is_still(Chunk(nudged), pose, 0.004)
    assert is_still(Chunk(nudged, unguided_actions=holding), pose, 0.004)
    assert not is_still(Chunk(holding, unguided_actions=nudged), pose, 0.004)


def test_the_weights_digest_names_the_model_whatever_path_the_checkpoint_stores(models, tmp_path):
    """A checkpoint trained into another folder stores other paths: another file digest, the same weights
    digest; another weight changes it. The run's provenance.json records both, and the CPU kernels it was trained on."""
    import json

    import torch

    from grits_lab.evaluation.methods import file_digest, weights_digest

    checkpoint = torch.load(models["policy"], map_location="cpu", weights_only=True)
    trained_on = checkpoint["cpu_kernels"]  # what the fixture's training computed with
    assert trained_on.startswith("numpy ") and "; torch " in trained_on
    moved = {**checkpoint, "train_config": {**checkpoint.get("train_config", {}), "output_dir": "elsewhere/policy"},
             "cpu_kernels": "numpy X86_V3; openblas Haswell; torch AVX2"}
    torch.save(moved, tmp_path / "moved.pt")
    assert file_digest(tmp_path / "moved.pt") != file_digest(models["policy"])
    assert weights_digest(tmp_path / "moved.pt") == weights_digest(models["policy"])
    first = next(iter(moved["policy"]["model"]))
    moved["policy"]["model"][first] = moved["policy"]["model"][first] + 1e-6
    torch.save(moved, tmp_path / "changed.pt")
    assert weights_digest(tmp_path / "changed.pt") != weights_digest(models["policy"])
    assert weights_digest(models["demos"]) is None  # a dataset directory has no weights
    evaluate(eval_config(models, tmp_path / "run", methods=["dp"], scoop={"max_steps": 12, "min_steps": 0}), progress=False)
    recorded = json.loads((tmp_path / "run" / "provenance.json").read_text())["methods"]["dp"]["checkpoints"]["policy"]
    assert recorded == {"path": models["policy"], "sha256_16": file_digest(models["policy"]),
                        "weights_sha256_16": weights_digest(models["policy"]), "trained on cpu kernels": trained_on}


def test_resuming_records_of_other_cpu_kernels_warns_and_names_both(tmp_path):
    from grits_lab.evaluation.evaluation_run import other_kernels_note
    from grits_lab.versions import cpu_kernels

    here, there = cpu_kernels(), "numpy OTHER; openblas OTHER; torch OTHER"  # no CPU reads so
    path = tmp_path / "episodes.parquet"
    assert other_kernels_note(path, [{"cpu_kernels": here}, {"cpu_kernels": None}, {}]) == ""  # own or unnamed: nothing to say
    note = other_kernels_note(path, [{"cpu_kernels": here}, {"cpu_kernels": there}, {"cpu_kernels": there}])
    assert note.startswith(f"warning: 2 records in {path} ran on CPU kernels `{there}`, this machine runs `{here}`")
