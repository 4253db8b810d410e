"""What `grits-lab evaluate` refuses before the first episode: mismatched or misplaced checkpoints, unknown levels."""

from __future__ import annotations

import math

import pytest
from tests.evaluation.eval_helpers import eval_config

from grits_lab.errors import ConfigError
from grits_lab.evaluation.evaluation_run import evaluate
from grits_lab.spillage.predictor_checkpoint import read_checkpoint
from grits_lab.training.checkpoints import save_checkpoint


@pytest.mark.parametrize("stored_as, refusal", [
    ("n_action_steps", r"`checkpoints.predictor` judges chunks of 8 actions, .* executes 12"),
    ("chunk_len", r"pred8.pt: `model.chunk_len` is the chunk length's name before scoop-v4, .* train the predictor again"),
])
def test_a_predictor_that_judges_other_chunks_than_the_policy_executes_is_refused(models, tmp_path, stored_as, refusal):
    payload = read_checkpoint(models["predictor"])
    model = payload["config"]["model"]
    del model["n_action_steps"]
    model[stored_as] = 8  # the policy executes 12; chunk_len: the name predictors trained before scoop-v4 store
    save_checkpoint(tmp_path / "pred8.pt", payload)
    config = eval_config(models, tmp_path / "run", methods=["dp", "grits"], checkpoints={"predictor": str(tmp_path / "pred8.pt")})
    with pytest.raises(ConfigError, match=refusal):
        evaluate(config, progress=False)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("key, other, kind", [
    ("predictor", "policy", "spillage predictor"),
    ("policy", "bc", "diffusion policy"),
    ("bc", "policy", "behavior-cloning"),
])
def test_a_checkpoint_of_another_kind_than_its_key_says_is_refused(models, tmp_path, key, other, kind):
    config = eval_config(models, tmp_path / "run", methods=["dp", "grits", "bc"], checkpoints={key: models[other]})
    with pytest.raises(ConfigError, match=rf"`checkpoints.{key}` is not a {kind} checkpoint"):
        evaluate(config, progress=False)
    assert not (tmp_path / "run").exists()


def test_a_level_no_food_has_is_refused_by_name(models, tmp_path):
    config = eval_config(models, tmp_path / "run", levels=["low", "medum"])
    with pytest.raises(ConfigError, match=r"`levels` names 'medum'"):
        evaluate(config, progress=False)
    assert not (tmp_path / "run").exists()


def test_a_planted_policy_checkpoint_is_refused_in_one_line_before_the_run_and_never_runs(models, tmp_path, plant_pickle, capsys):
    planted = tmp_path / "policy.pt"
    marker = plant_pickle(models["policy"], planted)
    err = _evaluate_refused(eval_config(models, tmp_path / "run", methods=["dp"], checkpoints={"policy": str(planted)}), tmp_path, capsys)
    assert len(err) == 1 and f"refused checkpoint {planted}" in err[0]
    assert not marker.exists() and not (tmp_path / "run").exists()


@pytest.mark.ray
def test_a_cluster_where_nothing_answers_is_refused_in_one_line_before_the_run_directory_exists(models, tmp_path, capsys, monkeypatch):
    import yaml
    from tests.tune.sweep_helpers import free_port

    from grits_lab.cli import main
    from grits_lab.config import config_to_dict
    from grits_lab.runners import executor_config

    monkeypatch.setattr(executor_config, "CONNECT_TIMEOUT_S", 1.0)
    address = f"127.0.0.1:{free_port()}"  # closed again: nothing listens there
    path = tmp_path / "evaluate.yaml"
    path.write_text(yaml.safe_dump(config_to_dict(eval_config(models, tmp_path / "run", methods=["rule_based"], executor={"backend": "ray"}))))
    assert main(["evaluate", str(path), "--address", address, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"cannot connect to the Ray cluster at {address}" in err[0], err
    assert not (tmp_path / "run").exists()


def test_an_override_that_gives_guidance_twice_is_refused_naming_the_key_and_both_lines(models, tmp_path, capsys):
    import yaml

    from grits_lab.cli import main
    from grits_lab.config import config_to_dict

    base = tmp_path / "evaluate.yaml"
    base.write_text(yaml.safe_dump(config_to_dict(eval_config(models, tmp_path / "run", methods=["grits"]))))
    override = tmp_path / "override.yaml"
    override.write_text("guidance: {rho: 2.5, s: 60}\nguidance: {rho: 8.0}\n")
    assert main(["evaluate", str(base), "--override", str(override), "--serial", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"grits-lab: error: {override}: key `guidance` is given twice (lines 1 and 2); give it once"]
    assert not (tmp_path / "run").exists()


def test_records_of_another_protocol_are_not_resumed_and_checkpoints_name_theirs(models, tmp_path):
    import pandas as pd

    from grits_lab.errors import InputError
    from grits_lab.training.checkpoints import load_checkpoint
    from grits_lab.versions import PROTOCOL

    assert load_checkpoint(models["policy"])["protocol"] == PROTOCOL
    assert read_checkpoint(models["predictor"])["protocol"] == PROTOCOL
    run = tmp_path / "run"
    run.mkdir()
    old = {"run_id": "test", "method": "expert", "food": "chocolate_balls", "level": "low", "trial": 0, "seed": 1,
           "task_success": True, "spillage": False, "scoop_failure": False, "error": "", "rho": float("nan"), "s": -1}
    pd.DataFrame([{**old, "protocol": "scoop-v3"}]).to_parquet(run / "episodes.parquet", index=False)
    config = eval_config(models, run, methods=["expert"])
    with pytest.raises(InputError, match=rf"holds episodes of protocol scoop-v3, but this code runs {PROTOCOL} .*--restart"):
        evaluate(config, progress=False)
    # a file written before the column existed, without the stage x cause columns of scoop-v4, is older too
    pd.DataFrame([old]).to_parquet(run / "episodes.parquet", index=False)
    with pytest.raises(InputError, match=r"protocol unversioned \(before scoop-v4\)"):
        evaluate(config, progress=False)


def test_a_planted_file_named_as_scone_demos_is_refused_in_one_line_and_never_runs(models, tmp_path, plant_pickle, capsys):
    planted = tmp_path / "demos.pt"
    marker = plant_pickle(models["policy"], planted)
    err = _evaluate_refused(eval_config(models, tmp_path / "run", methods=["scone"], checkpoints={"demos": str(planted)}), tmp_path, capsys)
    assert len(err) == 1 and "`checkpoints.demos`" in err[0] and str(planted) in err[0], err
    assert not marker.exists() and not (tmp_path / "run").exists()


def test_provenance_reads_a_planted_checkpoint_without_running_it(models, tmp_path, plant_pickle):
    """The identity provenance records (weights digest, training kernels) comes from the bytes read once,
    through the same tensors-only loader as the run's: a file swapped in after the check runs nothing."""
    from grits_lab.errors import InputError
    from grits_lab.evaluation.methods import checkpoint_identity, weights_digest

    planted = tmp_path / "policy.pt"
    marker = plant_pickle(models["policy"], planted)
    with pytest.raises(InputError, match=f"refused checkpoint {planted}"):
        checkpoint_identity(planted)
    with pytest.raises(InputError, match=f"refused checkpoint {planted}"):
        weights_digest(planted)
    assert not marker.exists()


def _evaluate_refused(config, tmp_path, capsys, changes: dict | None = None) -> list[str]:
    """`grits-lab evaluate` of `config` (with `changes` merged into its mapping) written to a file:
    asserts exit 2 and returns the lines of stderr."""
    import yaml

    from grits_lab.cli import main
    from grits_lab.config import config_to_dict, merge_mappings

    path = tmp_path / "evaluate.yaml"
    path.write_text(yaml.safe_dump(merge_mappings(config_to_dict(config), changes or {})))
    assert main(["evaluate", str(path), "--serial", "--no-progress"]) == 2
    return capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("changes, refusal", [
    ({"trials": 10**9}, "`trials` must be in [1, 10000]"),
    ({"first_trial": 10**21}, "`first_trial` must be a 64-bit integer"),
    ({"first_trial": 2**31 - 1}, "`first_trial` must be in [0, 2147483647 - trials]"),
    ({"guidance": {"rho": math.inf}}, "`guidance.rho` must be a finite number. Got inf."),
    ({"guidance": {"rho": math.nan}}, "`guidance.rho` must be a finite number. Got nan."),
    ({"guidance": {"s": 1000000}}, "`guidance.s` is 1000000, but the policy of `checkpoints.policy` trained on 100 timesteps"),
    ({"guidance": {"grad_clip": math.inf}}, "`guidance.grad_clip` must be a finite number"),
    ({"posthoc": {"rho": math.inf}}, "`posthoc.rho` must be a finite number"),
    ({"transfer": {"clearance": math.inf}}, "`transfer.clearance` must be a finite number"),
])
def test_a_number_the_run_cannot_use_is_refused_in_one_line_before_any_directory_or_episode(models, tmp_path, capsys, changes, refusal):
    err = _evaluate_refused(eval_config(models, tmp_path / "run", methods=["grits"]), tmp_path, capsys, changes)
    assert len(err) == 1 and refusal in err[0], err
    assert not (tmp_path / "run").exists()


def test_a_missing_checkpoint_is_reported_before_the_episode_list_is_built(models, tmp_path, capsys, monkeypatch):
    from grits_lab.evaluation import evaluation_run

    def no_episode_list(config):
        raise AssertionError("the episode list was built before the checkpoints were checked")

    monkeypatch.setattr(evaluation_run, "episode_keys", no_episode_list)
    config = eval_config(models, tmp_path / "run", methods=["dp"], checkpoints={"policy": str(tmp_path / "absent.pt")})
    err = _evaluate_refused(config, tmp_path, capsys)
    assert len(err) == 1 and f"`checkpoints.policy` not found: {tmp_path / 'absent.pt'}" in err[0], err
