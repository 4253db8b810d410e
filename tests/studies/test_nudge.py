"""The outcome-sensitivity study's nudge (studies/outcome_sensitivity/hooks.py), run through the scoop hook."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from grits_lab.errors import ConfigError, InputError
from grits_lab.evaluation.evaluation_run import evaluate
from studies.outcome_sensitivity.hooks import OutcomeHook
from tests.evaluation.eval_helpers import eval_config


def test_a_nudge_moves_every_executed_scoop_action_rigidly_and_a_run_holds_one_nudge(models, tmp_path):
    """The nudge hook: the same open-loop scoop (the scripted expert's) runs 3 mm away along one
    seeded direction; the record says so, and records of another nudge are not resumed."""
    from grits_lab.data.format import read_episode

    runs = {}
    for offset in (0.0, 0.003):
        config = eval_config(models, tmp_path / f"offset_{offset}", methods=["expert"], rollout_chunks=True)
        row = evaluate(config, progress=False, hook=OutcomeHook(offset=offset)).iloc[0]
        episode = next((tmp_path / f"offset_{offset}" / "rollout_chunks" / "expert" / "episodes").glob("*.npz"))
        runs[offset] = (row, read_episode(episode)[0]["trajectory"].astype(np.float64))
    (plain, plain_actions), (moved, moved_actions) = runs[0.0], runs[0.003]
    assert plain["scoop_action_offset_m"] == 0.0 and moved["scoop_action_offset_m"] == 0.003
    assert plain["seed"] == moved["seed"] and len(plain_actions) == len(moved_actions)
    shift = moved_actions - plain_actions
    expected = OutcomeHook(offset=0.003).offset_vector(int(plain["seed"]))
    np.testing.assert_allclose(shift, np.broadcast_to(expected, shift.shape), atol=1e-6)  # float32 actions
    assert math.isclose(np.linalg.norm(expected[:3]), 0.003) and not expected[3:].any()
    assert not OutcomeHook().offset_vector(int(plain["seed"])).any()
    assert not np.allclose(OutcomeHook(offset=0.003).offset_vector(int(plain["seed"]) + 1), expected)
    other_draw = OutcomeHook(offset=0.003, offset_draw=1).offset_vector(int(plain["seed"]))
    assert math.isclose(np.linalg.norm(other_draw[:3]), 0.003) and not np.allclose(other_draw, expected)
    with pytest.raises(InputError, match="scoop_action_offset_draw 0"):
        evaluate(eval_config(models, tmp_path / "offset_0.003", methods=["expert"], rollout_chunks=True), progress=False,
                 hook=OutcomeHook(offset=0.003, offset_draw=1))
    with pytest.raises(InputError, match="scoop_action_offset_m 0, "):
        evaluate(eval_config(models, tmp_path / "offset_0.0", methods=["expert"], rollout_chunks=True), progress=False,
                 hook=OutcomeHook(offset=0.001))
    with pytest.raises(InputError, match="--offset must be in"):
        OutcomeHook(offset=-0.001)


def test_an_evaluation_config_that_sets_a_retired_scoop_key_names_the_study_and_an_off_one_loads(models, tmp_path):
    """Run directories written before the hook store the nudge's keys at "off": they still load; a key
    that is set is one error naming it and the study's command."""
    from grits_lab.config import config_to_dict
    from grits_lab.evaluation.evaluation_config import load_evaluation_config

    path = tmp_path / "old.yaml"
    data = config_to_dict(eval_config(models, tmp_path))
    path.write_text(yaml.safe_dump({**data, "scoop": {**data["scoop"], "action_offset": 0.0, "branch_draw": 0}}))
    assert load_evaluation_config(path).scoop == eval_config(models, tmp_path).scoop
    path.write_text(yaml.safe_dump({**data, "scoop": {**data["scoop"], "action_offset": 0.0005}}))
    with pytest.raises(ConfigError, match=r"`scoop.action_offset` is no longer an evaluation setting.*studies.outcome_sensitivity"):
        load_evaluation_config(path)
