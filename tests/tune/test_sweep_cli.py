"""`grits-lab sweep` from the command line: clear one-line failures and a full run on the stand-in."""

from __future__ import annotations

import json
import time
from urllib.parse import unquote

import pytest
import yaml
from tests.tune.sweep_helpers import free_port

from grits_lab.cli import main
from grits_lab.errors import StorageError
from grits_lab.tune.storage import open_storage, redact


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("grits-lab: error: "), err
    return err[0]


def test_unreachable_postgres_url_is_rejected_quickly_without_the_password(sweep_file, capsys):
    url = f"postgresql://grits:hunter2@127.0.0.1:{free_port()}/sweeps"
    start = time.monotonic()
    assert main(["sweep", str(sweep_file()), "--storage", url, "--no-progress"]) == 2
    line = one_error_line(capsys)
    assert "cannot reach storage postgresql://grits:***@127.0.0.1" in line and "hunter2" not in line
    assert time.monotonic() - start < 20


PASSWORDS = ["S3cr3t/x", "S3cr/et", "pa:ss:wd", "S3cr%2Fet%3A", "p?w#d"]  # `/`, `:`, percent-escapes, query marks


@pytest.mark.parametrize("password", PASSWORDS)
def test_a_password_is_hidden_whole_whatever_it_holds(password):
    shown = redact(f"postgresql://grits:{password}@127.0.0.1:5999/sweeps")
    assert shown == "postgresql://grits:***@127.0.0.1:5999/sweeps"
    assert redact("postgresql://127.0.0.1/sweeps?sslmode=require&password=S3cr/et") == "postgresql://127.0.0.1/sweeps?sslmode=require&password=***"
    assert redact("postgresql://grits@127.0.0.1/sweeps") == "postgresql://grits@127.0.0.1/sweeps"


@pytest.mark.parametrize("password", ["S3cr3t/x", "pa:ss", "S3cr%2Fet"])
def test_an_unreachable_url_is_refused_in_one_line_without_any_of_its_password(sweep_file, capsys, password):
    url = f"postgresql://u:{password}@127.0.0.1:{free_port()}/db"
    assert main(["sweep", str(sweep_file()), "--storage", url, "--no-progress"]) == 2
    line = one_error_line(capsys)
    assert "postgresql://u:***@127.0.0.1" in line
    assert all(part not in line for part in {password, unquote(password), "S3cr", "ss"} if part)


def test_a_raw_at_sign_in_a_password_is_refused_without_its_tail(sweep_file, capsys, tmp_path):
    url = f"postgresql://u:p@ssw0rd@127.0.0.1:{free_port()}/db"
    assert main(["sweep", str(sweep_file()), "--storage", url, "--no-progress"]) == 2
    line = one_error_line(capsys)
    assert "holds a raw `@`: write it as %40" in line and "ssw0rd" not in line
    assert not (tmp_path / "results").exists()


@pytest.mark.postgres
def test_a_sweep_on_postgresql_never_prints_or_stores_its_password(sweep_file, postgres_url, tmp_path, capfd):
    password = "S3cr/et:x%2F"  # the test server trusts every password: the URL is real, the password is only text
    url = postgres_url.replace("postgres@", f"postgres:{password}@")
    config = sweep_file("secret", n_trials=2, synthetic={"seconds_per_episode": 0.0})
    assert main(["sweep", str(config), "--storage", url, "--no-progress", "--no-plots"]) == 0
    out, err = capfd.readouterr()
    summary = json.loads((tmp_path / "results" / "secret" / "summary.json").read_text())
    assert summary["storage"].startswith("postgresql://postgres:***@127.0.0.1")
    written = "".join(p.read_text(errors="replace") for p in (tmp_path / "results").rglob("*") if p.is_file())
    for text in (out, err, written):
        assert "S3cr" not in text


@pytest.mark.parametrize("spec, message", [
    ("redis://localhost:6379/0", "unsupported storage URL"),
    ("sqlite:////nonexistent-dir/deeper/x.db", "cannot reach storage"),
])
def test_bad_storage_specs_are_rejected(tmp_path, spec, message):
    with pytest.raises(StorageError, match=message):
        open_storage(spec, tmp_path / "j.log")


def test_journal_path_that_is_a_directory_is_rejected(tmp_path):
    with pytest.raises(StorageError, match="is a directory"):
        open_storage(str(tmp_path), tmp_path / "j.log")


def test_grits_evaluator_needs_its_config_and_checkpoints(sweep_file, tmp_path, capsys):
    missing_config = sweep_file(evaluator="grits", evaluation={"config": str(tmp_path / "none.yaml")})
    assert main(["sweep", str(missing_config)]) == 2
    assert "evaluation config not found" in one_error_line(capsys)
    (tmp_path / "eval.yaml").write_text("{}\n")
    missing_ckpt = sweep_file(evaluator="grits", evaluation={"config": str(tmp_path / "eval.yaml"),
                                                             "checkpoints": [str(tmp_path / "policy.pt")]})
    assert main(["sweep", str(missing_ckpt)]) == 2
    assert "checkpoint not found" in one_error_line(capsys)
    assert not (tmp_path / "results").exists()  # failed before any storage was created


@pytest.mark.ray
def test_a_grits_sweep_on_a_cluster_where_nothing_answers_is_refused_before_the_study_exists(sweep_file, tmp_path, capsys, monkeypatch):
    from tests.tune.sweep_helpers import REPO

    from grits_lab.runners import executor_config
    from grits_lab.tune import grits_binding

    monkeypatch.setattr(executor_config, "CONNECT_TIMEOUT_S", 1.0)
    monkeypatch.setattr(grits_binding, "method_checkpoints", lambda method, checkpoints: {})  # no trained models needed
    monkeypatch.setattr(grits_binding, "check_method_checkpoints", lambda method, paths: None)  # checked before the cluster
    monkeypatch.setenv("RAY_ADDRESS", "")  # --address sets it; restored at teardown
    address = f"127.0.0.1:{free_port()}"
    config = sweep_file(evaluator="grits", evaluation={"config": str(REPO / "experiments" / "evaluate_quick.yaml"), "checkpoints": []})
    assert main(["sweep", str(config), "--address", address, "--no-progress"]) == 2
    assert f"cannot connect to the Ray cluster at {address}" in one_error_line(capsys)
    assert not (tmp_path / "results").exists()


def test_a_misspelled_key_in_the_evaluation_config_stops_the_sweep_before_any_trial(sweep_file, tmp_path, capsys):
    (tmp_path / "eval.yaml").write_text("guidance: {rho: 1.0, treshold: 12}\n")
    config = sweep_file(evaluator="grits", evaluation={"config": str(tmp_path / "eval.yaml")})
    assert main(["sweep", str(config)]) == 2
    line = one_error_line(capsys)
    assert "eval.yaml" in line and "guidance.treshold" in line
    assert not (tmp_path / "results").exists()


def test_full_run_then_report_only(sweep_file, tmp_path, capsys):
    config = sweep_file(n_trials=3)
    assert main(["sweep", str(config), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "defaults  trial 0: rho=2.5 s=30" in out and "optuna-dashboard" in out
    folder = tmp_path / "results" / "study"
    for name in ("trials.csv", "trials.parquet", "best.yaml", "summary.json", "pareto.png", "importance.png", "journal.log"):
        assert (folder / name).exists(), name
    assert len(list((folder / "records").glob("trial_*.parquet"))) == 3
    (folder / "best.yaml").unlink()
    assert main(["sweep", str(config), "--report-only", "--no-plots"]) == 0
    assert set(yaml.safe_load((folder / "best.yaml").read_text())) == {"guidance"}


def test_changed_search_space_on_an_existing_study_is_rejected(sweep_file, capsys):
    assert main(["sweep", str(sweep_file(n_trials=1)), "--no-progress", "--no-plots"]) == 0
    capsys.readouterr()
    assert main(["sweep", str(sweep_file(n_trials=1, rho={"high": 9.0})), "--no-progress"]) == 2
    assert "different search space" in one_error_line(capsys)


def test_a_journal_with_a_torn_last_record_is_cut_back_and_the_sweep_resumes(sweep_file, capsys):
    config = sweep_file(n_trials=2)
    assert main(["sweep", str(config), "--no-progress", "--no-plots"]) == 0
    journal = config.parent / "results" / "study" / "journal.log"
    whole = journal.read_bytes()
    with open(journal, "ab") as fh:  # what a kill or a full disk mid-append leaves
        fh.write(b'{"op_code": 5, "worker_id": "dead", "trial_id": 1, "us')
    capsys.readouterr()
    assert main(["sweep", str(sweep_file(n_trials=3)), "--no-progress", "--no-plots"]) == 0
    captured = capsys.readouterr()
    assert "half-written record" in captured.err and "trials: {'COMPLETE': 3}" in captured.out
    assert journal.read_bytes().startswith(whole)
    # and every later run reads it
    assert main(["sweep", str(sweep_file(n_trials=3)), "--report-only", "--no-plots"]) == 0


@pytest.mark.parametrize("validation, key, name", [
    ({"foods": ["soybeans"], "levels": ["medum"]}, "validation.levels", "medum"),
    ({"foods": ["soybean"], "levels": ["low"]}, "validation.foods", "soybean"),
])
def test_validation_names_the_food_library_lacks_are_refused_before_the_study_exists(
        sweep_file, tmp_path, capsys, validation, key, name):
    from tests.tune.sweep_helpers import REPO

    config = sweep_file(evaluator="grits", validation=validation,
                        evaluation={"config": str(REPO / "experiments" / "evaluate_quick.yaml"), "checkpoints": []})
    assert main(["sweep", str(config), "--no-progress"]) == 2
    line = one_error_line(capsys)
    assert f"`{key}`" in line and repr(name) in line
    assert not (tmp_path / "results").exists()


def test_the_summary_names_only_the_files_it_wrote(sweep_file, tmp_path, capsys):
    assert main(["sweep", str(sweep_file(n_trials=2)), "--no-progress", "--no-plots"]) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if l.startswith("outputs in "))
    listed = line.split(": ", 1)[1].split(", ")
    folder = tmp_path / "results" / "study"
    assert "pareto.png" not in listed and "importance.png" not in listed
    assert all((folder / name).exists() for name in listed) and "trials.csv" in listed
