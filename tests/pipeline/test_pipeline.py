"""The pipeline wires stages together, skips up-to-date stages and re-runs changed ones."""

from __future__ import annotations

import json

import pytest
import yaml

from grits_lab.cli import main
from grits_lab.errors import ConfigError
from grits_lab.pipeline.pipeline_config import load_pipeline_config
from grits_lab.pipeline.pipeline_run import STATE_FILE, run_pipeline


def _write(path, data):
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture()
def demos_file(tmp_path):
    return _write(tmp_path / "demos.yaml", {
        "kind": "demos", "foods": ["soybeans"], "levels": ["low"], "bowl_configs": 1,
        "cloud": {"n_points": 64}, "executor": {"backend": "serial"},
    })


def test_bad_pipeline_configs_name_the_problem(tmp_path, demos_file):
    cases = [
        ({"name": "x", "output_dir": str(tmp_path), "stages": {"demoz": {"config": str(demos_file)}}}, "unknown stage `stages.demoz`"),
        ({"name": "x", "output_dir": str(tmp_path), "stages": {"policy": {"config": str(demos_file)}}}, "stage `policy` needs stage `demos`"),
        ({"name": "x", "output_dir": str(tmp_path), "stages": {"demos": {"config": "nope.yaml"}}}, "`stages.demos.config`: file not found"),
        ({"name": "x", "output_dir": str(tmp_path), "workers": 0, "stages": {}}, "`workers` must be at least 1"),
        ({"name": "x", "output_dir": str(tmp_path), "stages": {"demos": {"config": str(demos_file), "overide": {}}}}, "unknown key `stages.demos.overide`"),
    ]
    for data, fragment in cases:
        with pytest.raises(ConfigError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
            load_pipeline_config(_write(tmp_path / "p.yaml", data))


def test_shipped_pipelines_load():
    for name in ("experiments/quickstart.yaml", "experiments/paper.yaml"):
        config = load_pipeline_config(name)
        assert config.ordered_stages()[0] == "demos" and config.ordered_stages()[-1] == "report"


def test_up_to_date_stage_is_skipped_and_changed_stage_reruns(tmp_path, demos_file, capsys):
    out = tmp_path / "run"
    pipeline = _write(tmp_path / "pipeline.yaml", {
        "name": "tiny", "output_dir": str(out), "stages": {"demos": {"config": str(demos_file)}},
    })
    config = load_pipeline_config(pipeline)
    first = run_pipeline(config, progress=False)
    assert first["demos"]["status"] == "done"
    episodes = sorted((out / "datasets" / "demos" / "episodes").glob("*.npz"))
    assert len(episodes) == 1
    wired = yaml.safe_load((out / "configs" / "demos.yaml").read_text())
    assert wired["output_dir"] == str(out / "datasets" / "demos")

    second = run_pipeline(config, progress=False)
    assert second["demos"]["status"] == "skipped"
    assert sorted((out / "datasets" / "demos" / "episodes").glob("*.npz")) == episodes

    changed = _write(tmp_path / "pipeline.yaml", {
        "name": "tiny", "output_dir": str(out),
        "stages": {"demos": {"config": str(demos_file), "overrides": {"seed": 5}}},
    })
    third = run_pipeline(load_pipeline_config(changed), progress=False)
    assert third["demos"]["status"] == "done"
    assert third["demos"]["fingerprint"] != first["demos"]["fingerprint"]
    state = json.loads((out / STATE_FILE).read_text())
    assert state["demos"]["fingerprint"] == third["demos"]["fingerprint"]
    assert "config changed" in capsys.readouterr().err


def test_cli_rejects_unknown_stage_selection(tmp_path, demos_file, capsys):
    pipeline = _write(tmp_path / "pipeline.yaml", {
        "name": "tiny", "output_dir": str(tmp_path / "run"), "stages": {"demos": {"config": str(demos_file)}},
    })
    assert main(["pipeline", str(pipeline), "--only", "policy"]) == 2
    assert "unknown stage `policy`" in capsys.readouterr().err


def test_the_sweep_stage_keeps_the_sweep_files_evaluation_overrides(tmp_path):
    from grits_lab.config import load_yaml
    from grits_lab.pipeline.pipeline_run import stage_config_text
    from grits_lab.pipeline.stages import Layout

    data = load_yaml("experiments/paper.yaml")
    data["output_dir"] = str(tmp_path / "paper")
    data["stages"]["sweep"] = {"config": "sweeps/grits_cpu_normalized.yaml"}
    config = load_pipeline_config(_write(tmp_path / "p.yaml", data))
    layout = Layout(tmp_path / "paper")
    wired = yaml.safe_load(stage_config_text("sweep", config, layout))
    evaluation = wired["evaluation"]
    assert evaluation["overrides"] == {"guidance": {"step": "normalized"}}  # rho is tuned on the step the file names
    assert evaluation["config"] == str(layout.sweep_evaluation_config)  # the pipeline's own links win
    assert all(str(tmp_path) in path for path in evaluation["checkpoints"])


def test_the_quickstarts_evaluation_runs_with_its_sweeps_best_point(tmp_path):
    from grits_lab.config import load_yaml
    from grits_lab.pipeline.pipeline_run import stage_config_text
    from grits_lab.pipeline.stages import Layout

    data = load_yaml("experiments/quickstart.yaml")
    data["output_dir"] = str(tmp_path / "quick")
    config = load_pipeline_config(_write(tmp_path / "p.yaml", data))
    stages = config.ordered_stages()
    assert "sweep" in stages and stages.index("sweep") < stages.index("evaluate")
    layout = Layout(tmp_path / "quick")
    sweep = yaml.safe_load(stage_config_text("sweep", config, layout))
    assert sweep["evaluation"]["config"] == str(layout.sweep_evaluation_config)
    assert sweep["objective"]["mode"] == "multi" and sweep["reference"] == ["dp"]
    assert sweep["enqueue"][0] == {"rho": 2.5, "s": 30}  # the paper's defaults run first
    untuned = yaml.safe_load(stage_config_text("evaluate", config, layout))
    episodes = {(e.food, e.level, e.seed) for e in load_study_config_from(sweep, tmp_path)}
    assert untuned["seed"] != sweep["validation"]["seed"] and episodes  # the sweep tunes on its own seeds
    layout.sweep_dir.mkdir(parents=True)
    (layout.sweep_dir / "best.yaml").write_text("# trial 3\nguidance: {rho: 0.7, s: 18}\n")
    tuned = yaml.safe_load(stage_config_text("evaluate", config, layout))
    assert (tuned["guidance"]["rho"], tuned["guidance"]["s"]) == (0.7, 18)
    assert {k: v for k, v in tuned["guidance"].items() if k not in ("rho", "s")} == \
        {k: v for k, v in untuned["guidance"].items() if k not in ("rho", "s")}
    assert yaml.safe_load(stage_config_text("evaluate", config, layout, tuned=False))["guidance"] == untuned["guidance"]


def load_study_config_from(sweep: dict, tmp_path):
    """The validation episodes of a wired sweep mapping, read against the quickstart's evaluation config."""
    from grits_lab.tune.study_config import load_study_config

    data = {**sweep, "evaluation": {**sweep["evaluation"], "config": "experiments/evaluate_quick.yaml"}}
    return load_study_config(_write(tmp_path / "sweep.yaml", data)).episodes()


@pytest.mark.parametrize("stage, overrides, fragment", [
    ("policy", {"policy": {"unet": {"down_dimz": [32, 64]}}},
     "stage `policy` (experiments/policy_paper.yaml with its overrides): unknown key `policy.unet.down_dimz`"),
    ("evaluate", {"foods": ["sagoo"]}, "stage `evaluate` (experiments/evaluate_paper.yaml with its overrides): `foods` names 'sagoo'"),
    ("sweep", {"validation": {"foods": ["sagoo"]}}, "`validation.foods` names 'sagoo'"),
    ("sweep", {"evaluation": {"overrides": {"guidance": {"stepp": "normalized"}}}}, "guidance.stepp"),
])
def test_a_bad_key_in_a_later_stage_fails_before_the_first_stage_runs(tmp_path, capsys, stage, overrides, fragment):
    from grits_lab.config import load_yaml

    data = load_yaml("experiments/paper.yaml")
    out = tmp_path / "run"
    data["output_dir"] = str(out)
    data["stages"][stage]["overrides"] = {**data["stages"][stage].get("overrides", {}), **overrides}
    pipeline = _write(tmp_path / "pipeline.yaml", data)
    assert main(["pipeline", str(pipeline), "--no-progress"]) == 2
    err = [line for line in capsys.readouterr().err.strip().splitlines() if "error" in line]
    assert len(err) == 1 and fragment in err[0] and str(tmp_path) not in err[0].replace(str(pipeline), "")
    assert not out.exists()  # nothing was written, the first stage never started


def test_the_shipped_pipelines_stage_configs_pass_the_check(tmp_path):
    from grits_lab.config import load_yaml
    from grits_lab.pipeline.pipeline_run import stage_config_text
    from grits_lab.pipeline.stages import Layout, check

    for name in ("experiments/quickstart.yaml", "experiments/study_cpu.yaml", "experiments/paper.yaml"):
        data = load_yaml(name)
        data["output_dir"] = str(tmp_path / "out")
        config = load_pipeline_config(_write(tmp_path / "p.yaml", data))
        texts = {stage: stage_config_text(stage, config, Layout(tmp_path / "out")) for stage in config.ordered_stages()}
        for stage in texts:
            check(stage, texts, config.stages[stage].config)


def test_a_cluster_address_where_nothing_answers_fails_before_the_pipeline_directory_exists(tmp_path, demos_file, capsys):
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]  # closed again: nothing listens there
    out = tmp_path / "run"
    pipeline = _write(tmp_path / "pipeline.yaml", {"name": "tiny", "output_dir": str(out), "address": f"127.0.0.1:{port}",
                                                   "stages": {"demos": {"config": str(demos_file)}}})
    assert main(["pipeline", str(pipeline), "--no-progress"]) == 2
    assert f"cannot connect to the Ray cluster at 127.0.0.1:{port}" in capsys.readouterr().err
    assert not out.exists()


def test_a_second_pipeline_on_one_output_directory_is_refused_naming_the_first(tmp_path, demos_file, capsys, hold_directory):
    out = tmp_path / "run"
    out.mkdir()
    holder = hold_directory(out, "pipeline")
    pipeline = _write(tmp_path / "pipeline.yaml", {"name": "tiny", "output_dir": str(out), "stages": {"demos": {"config": str(demos_file)}}})
    assert main(["pipeline", str(pipeline), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{out} is being written by `grits-lab pipeline` (pid {holder.pid} on" in err[0], err
    assert [p.name for p in out.iterdir()] == [".grits-lab.lock"]

@pytest.mark.parametrize("storage, mode", [("postgresql://u:S3cr3t/x@127.0.0.1:5999/db", 0o600), (None, None)])
def test_a_sweep_stage_config_holding_a_storage_password_is_written_owner_only(tmp_path, capsys, monkeypatch, storage, mode):
    from grits_lab.config import load_yaml
    from grits_lab.io import _ordinary_mode

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    data = load_yaml("experiments/paper.yaml")
    data["output_dir"] = str(tmp_path / "paper")
    data["stages"]["sweep"]["overrides"] = {"storage": storage}
    pipeline = _write(tmp_path / "p.yaml", data)
    assert main(["pipeline", str(pipeline), "--only", "sweep", "--no-progress"]) == 2  # the evaluate stage has not run
    written = tmp_path / "paper" / "configs" / "sweep.yaml"
    assert written.stat().st_mode & 0o777 == (mode or _ordinary_mode(written))
    assert yaml.safe_load(written.read_text())["storage"] == storage  # the stage runs from this file
    assert "S3cr3t" not in capsys.readouterr().err


def test_the_report_stage_shows_every_training_runs_curves(tmp_path):
    from grits_lab.pipeline.stages import Layout, run, wire
    from grits_lab.training import MetricLogger
    from tests.report.synthetic_records import plausible_run

    layout = Layout(tmp_path / "pipe")
    for run_dir in (layout.policy_dir, layout.bc_dir, layout.predictor_dir("predictor")):
        logger = MetricLogger(run_dir, namespace="policy", tensorboard=False)
        logger.log(1, {"train_loss": 0.5, "lr": 1e-3, "val_loss": 0.6})
        logger.close()
    layout.evaluate_dir.mkdir(parents=True)
    plausible_run(0).to_parquet(layout.evaluate_dir / "episodes.parquet", index=False)
    config = _write(tmp_path / "report.yaml", wire("report", {}, layout, {"policy", "bc", "predictor", "evaluate", "report"}, None, None))
    summary = run("report", config, layout, progress=False)
    html = (layout.report_dir / "report.html").read_text()
    assert summary["output_dir"] == str(layout.report_dir)
    section = html.split("<h2>Training</h2>", 1)[1].split("</section>", 1)[0]
    assert section.count("<img") == 3 and all(f"Training: {d}" in section for d in (layout.policy_dir, layout.bc_dir))


def _carry_pipeline(tmp_path, **stage_files):
    files = {"spillage_carry": "experiments/spillage_carry_cpu.yaml", "predictor_horizon": "experiments/predictor_cpu_carry_horizon.yaml",
             **stage_files}
    return _write(tmp_path / "pipeline.yaml", {
        "name": "carry", "output_dir": str(tmp_path / "run"), "stages": {
            "demos": {"config": "experiments/demos_cpu.yaml"},
            "spillage_carry": {"config": files["spillage_carry"]},
            "policy": {"config": "experiments/policy_cpu.yaml"},
            "predictor_horizon": {"config": files["predictor_horizon"]},
            "evaluate": {"config": "experiments/evaluate_cpu.yaml", "overrides": {"methods": ["dp", "grits_horizon"]}},
        }})


def test_the_horizon_predictor_trains_on_the_carry_set_and_guides_grits_horizon(tmp_path):
    from grits_lab.pipeline.pipeline_run import stage_config_text
    from grits_lab.pipeline.stages import Layout, check

    config = load_pipeline_config(_carry_pipeline(tmp_path))
    layout = Layout(tmp_path / "run")
    assert config.ordered_stages() == ["demos", "spillage_carry", "policy", "predictor_horizon", "evaluate"]
    texts = {stage: stage_config_text(stage, config, layout) for stage in config.ordered_stages()}
    for stage in texts:
        check(stage, texts, config.stages[stage].config)
    carry = yaml.safe_load(texts["spillage_carry"])
    assert carry["output_dir"] == str(layout.dataset("spillage_carry")) and carry["base_trajectory"] == str(layout.dataset("demos"))
    predictor = yaml.safe_load(texts["predictor_horizon"])
    assert predictor["data"]["dataset"] == str(layout.dataset("spillage_carry")) and predictor["data"]["label"] == "horizon"
    evaluate = yaml.safe_load(texts["evaluate"])
    assert evaluate["checkpoints"]["predictor_horizon"] == str(layout.predictor_dir("predictor_horizon") / "best.pt")
    assert evaluate["checkpoints"]["predictor"] is None  # no chunk-label predictor stage in this pipeline


@pytest.mark.parametrize("stage, config_file, fragment", [
    ("spillage_carry", "experiments/spillage_cpu.yaml", "the spillage_carry stage collects trials that end with the evaluation's carry"),
    ("predictor_horizon", "experiments/predictor_cpu_carry_chunk.yaml", "needs `data.label: horizon`, not 'chunk'"),
])
def test_a_carry_stage_given_the_wrong_kind_of_config_fails_before_anything_runs(tmp_path, capsys, stage, config_file, fragment):
    pipeline = _carry_pipeline(tmp_path, **{stage: config_file})
    assert main(["pipeline", str(pipeline), "--no-progress"]) == 2
    err = [line for line in capsys.readouterr().err.strip().splitlines() if "error" in line]
    assert len(err) == 1 and fragment in err[0] and f"stage `{stage}`" in err[0]
    assert not (tmp_path / "run").exists()


def test_a_changed_stage_removes_its_own_outputs_but_never_what_a_link_points_at(tmp_path):
    from grits_lab.pipeline.pipeline_run import remove_outputs

    kept = tmp_path / "elsewhere" / "demos"
    kept.mkdir(parents=True)
    (kept / "episode.npz").write_bytes(b"data")
    stage = tmp_path / "pipeline" / "datasets"
    stage.mkdir(parents=True)
    (stage / "demos").symlink_to(kept, target_is_directory=True)
    (stage / "spillage").mkdir()
    (stage / "spillage" / "episode.npz").write_bytes(b"data")
    (stage / "episodes.parquet").write_bytes(b"data")
    remove_outputs([stage / "demos", stage / "spillage", stage / "episodes.parquet", stage / "absent"])
    assert not any(stage.iterdir())
    assert (kept / "episode.npz").read_bytes() == b"data"


def test_the_closing_summary_names_the_sweeps_best_point_its_front_and_the_reference(tmp_path):
    from grits_lab.pipeline.closing import closing_lines
    from grits_lab.pipeline.stages import Layout

    layout = Layout(tmp_path / "quick")
    layout.sweep_dir.mkdir(parents=True)
    point = {"trial": 1, "rho": 0.8, "s": 24, "success_rate": 0.75, "spillage_rate": 0.0}
    summary = {"best": point, "episodes_per_trial": 4, "pareto_front": [point],
               "reference": {"dp": {"success_rate": 0.5, "spillage_rate": 0.25}}, "dashboard": "optuna-dashboard J"}
    (layout.sweep_dir / "summary.json").write_text(json.dumps(summary))
    lines = closing_lines(layout, ["sweep"])
    assert lines == ["sweep: best rho 0.8, s 24 (trial 1: success 0.75, spillage 0.00 over 4 validation episodes; dp on the "
                     "same episodes: success 0.50, spillage 0.25); Pareto front: rho 0.8 s 24 (success 0.75, spillage 0.00); "
                     "optuna-dashboard J"]
    assert closing_lines(layout, ["demos"]) == []  # nothing for stages this pipeline lacks
