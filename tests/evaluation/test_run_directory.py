"""One run directory, several `grits-lab evaluate` invocations: one writer at a time, records and
their description kept together, and no resume across changed checkpoints."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pandas as pd
import pytest
import yaml
from tests.evaluation.eval_helpers import eval_config

from grits_lab.cli import main
from grits_lab.config import config_to_dict
from grits_lab.errors import InputError
from grits_lab.evaluation.evaluation_run import evaluate
from grits_lab.training.checkpoints import load_checkpoint, save_checkpoint

def _config_file(models, tmp_path, run_dir, **changes):
    path = tmp_path / f"evaluate-{len(list(tmp_path.glob('evaluate-*.yaml')))}.yaml"
    path.write_text(yaml.safe_dump(config_to_dict(eval_config(models, run_dir, **changes))))
    return path


def test_a_second_writer_is_refused_in_one_line_and_a_dead_holder_is_taken_over(models, tmp_path, capsys, hold_directory):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    holder = hold_directory(run_dir, "evaluate")
    config = _config_file(models, tmp_path, run_dir, methods=["rule_based"])
    assert main(["evaluate", str(config), "--serial", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{run_dir} is being written by `grits-lab evaluate` (pid {holder.pid} on" in err[0]
    assert sorted(p.name for p in run_dir.iterdir()) == [".grits-lab.lock"]  # nothing written
    os.kill(holder.pid, signal.SIGKILL)
    holder.wait()
    assert main(["evaluate", str(config), "--serial", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"taking over {run_dir / '.grits-lab.lock'} from `grits-lab evaluate` (pid {holder.pid}" in err
    assert len(pd.read_parquet(run_dir / "episodes.parquet")) == 1


def test_two_writers_started_together_never_lose_a_record(models, tmp_path):
    run_dir = tmp_path / "run"
    configs = [_config_file(models, tmp_path, run_dir, methods=[m]) for m in ("rule_based", "dp")]
    procs = [subprocess.Popen([sys.executable, "-m", "grits_lab.cli", "evaluate", str(c), "--serial", "--no-progress"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for c in configs]
    outcomes = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    records = pd.read_parquet(run_dir / "episodes.parquet")
    finished = sorted(m for (code, _), m in zip(outcomes, ("rule_based", "dp")) if code == 0)
    assert sorted(records["method"]) == finished  # what a writer reported finished is in the file
    for code, err in outcomes:
        assert code == 0 or (code == 2 and "is being written by `grits-lab evaluate`" in err), err


def test_records_of_earlier_invocations_stay_described(models, tmp_path):
    run_dir = tmp_path / "run"
    evaluate(eval_config(models, run_dir, methods=["rule_based"]), progress=False)
    records = evaluate(eval_config(models, run_dir, methods=["dp"]), progress=False)
    assert sorted(records["method"]) == ["dp", "rule_based"]
    described = yaml.safe_load((run_dir / "config.yaml").read_text())
    provenance = json.loads((run_dir / "provenance.json").read_text())
    assert described["methods"] == ["rule_based", "dp"]
    assert set(provenance["methods"]) == {"rule_based", "dp"}
    assert provenance["methods"]["dp"]["checkpoints"]["policy"]["path"] == models["policy"]


def test_the_directory_keeps_when_its_first_run_started_and_each_method_when_its_own_did(models, tmp_path):
    run_dir = tmp_path / "run"
    evaluate(eval_config(models, run_dir, methods=["rule_based"]), progress=False)
    first = json.loads((run_dir / "provenance.json").read_text())
    path = run_dir / "provenance.json"
    path.write_text(json.dumps({**first, "started (UTC)": "2026-01-02 03:04:05",
                                "methods": {"rule_based": {**first["methods"]["rule_based"], "started (UTC)": "2026-01-02 03:04:05"}}}))
    records = evaluate(eval_config(models, run_dir, methods=["dp"]), progress=False)
    provenance = json.loads(path.read_text())
    assert provenance["started (UTC)"] == "2026-01-02 03:04:05"  # the first run's, not this one's
    assert provenance["methods"]["rule_based"]["started (UTC)"] == "2026-01-02 03:04:05"
    assert provenance["methods"]["dp"]["started (UTC)"] > "2026-01-02 03:04:05"
    assert provenance["methods"]["dp"]["code git commit"] == provenance["code git commit"]
    # each record names the code that played it, so records joined from several runs keep theirs
    assert set(records.loc[records["method"] == "dp", "code_commit"]) == {provenance["code git commit"]}
    evaluate(eval_config(models, run_dir, methods=["dp"]), progress=False, restart=True)  # nothing kept: a fresh start
    assert json.loads(path.read_text())["started (UTC)"] > "2026-01-02 03:04:05"


def test_a_changed_checkpoint_is_refused_not_resumed_and_restart_starts_over(models, tmp_path):
    run_dir = tmp_path / "run"
    evaluate(eval_config(models, run_dir, methods=["dp"]), progress=False)
    before = pd.read_parquet(run_dir / "episodes.parquet")
    other = tmp_path / "other.pt"
    state = load_checkpoint(models["policy"])
    state["step"] += 1  # the same network, another file: another digest
    save_checkpoint(other, state)
    changed = eval_config(models, run_dir, methods=["dp"], checkpoints={"policy": str(other)})
    with pytest.raises(InputError, match=rf"holds `dp` episodes made with `checkpoints.policy` digest {before['checkpoint_policy'][0]}, but {other} has digest"):
        evaluate(changed, progress=False)
    assert pd.read_parquet(run_dir / "episodes.parquet").equals(before)
    assert json.loads((run_dir / "provenance.json").read_text())["methods"]["dp"]["checkpoints"]["policy"]["path"] == models["policy"]
    records = evaluate(changed, progress=False, restart=True)
    assert list(records["checkpoint_policy"]) != list(before["checkpoint_policy"])


def test_a_lab_method_recorded_earlier_stays_in_provenance_when_a_later_config_does_not_register_it(models, tmp_path):
    from grits_lab.config import config_from_dict
    from grits_lab.evaluation.evaluation_config import EvaluationConfig
    from tests.evaluation.test_custom_methods import tiny_config

    run_dir = tmp_path / "run"
    evaluate(config_from_dict(EvaluationConfig, tiny_config(tmp_path)), progress=False)
    records = evaluate(eval_config(models, run_dir, methods=["rule_based"]), progress=False)
    assert sorted(records["method"]) == ["rule_based", "torch_mlp"]
    assert yaml.safe_load((run_dir / "config.yaml").read_text())["methods"] == ["rule_based"]
    assert set(json.loads((run_dir / "provenance.json").read_text())["methods"]) == {"rule_based", "torch_mlp"}
