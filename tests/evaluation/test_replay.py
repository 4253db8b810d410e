"""Replaying recorded evaluation episodes: the replay reproduces the record exactly, says where it does not, films it."""

from __future__ import annotations

import json
import math
import re

import imageio.v2 as imageio
import pandas as pd
import pytest

from grits_lab.cli import main
from grits_lab.errors import InputError, StorageError
from grits_lab.report.replay import replay_episode
from grits_lab.sim.sim_config import CameraConfig

SMALL_CAMERA = CameraConfig(name="video", eye=(1.08, 0.14, 0.6), target=(0.47, 0.12, 0.07), fov_deg=50.0, width=96, height=72)


@pytest.fixture(scope="module")
def run(recorded_run):
    return recorded_run


def episode(records: pd.DataFrame, method: str) -> dict:
    row = records[records["method"] == method].iloc[0]
    return {"method": method, "food": row["food"], "level": row["level"], "trial": int(row["trial"])}


@pytest.mark.parametrize("method", ["dp", "grits"])
def test_a_replay_reproduces_every_recorded_metric(run, method):
    run_dir, records = run
    result = replay_episode(run_dir, **episode(records, method))
    assert result.matches, result.describe()
    for column in ("spilled", "scooped", "spillage", "scoop_success", "task_success", "first_spill_step", "n_plans", "spoon_coverage"):
        assert column in result.compared
    if method == "grits":
        assert "p_spill_after" in result.compared and result.rho == 2.5 and result.s == 30


def test_a_filmed_replay_is_the_same_episode_and_writes_a_captioned_video(run, tmp_path, capsys):
    run_dir, records = run
    video = tmp_path / "dp.mp4"
    result = replay_episode(run_dir, **episode(records, "dp"), video=video, camera=SMALL_CAMERA, every=5, progress=True)
    assert result.matches, result.describe()
    steps = int(result.replayed["scoop_steps"])
    # The progress bar on stderr counts every action played, the scoop's and the transfer's.
    final = capsys.readouterr().err.replace("\r", "\n").strip().splitlines()[-1]
    assert final.startswith("replaying dp ") and int(re.search(r"(\d+)action", final).group(1)) >= steps, final
    reader = imageio.get_reader(video)
    try:
        frames = reader.count_frames()
        first = reader.get_data(0)
        shapes = {reader.get_data(i).shape for i in range(frames)}
    finally:
        reader.close()
    assert frames == result.frames and frames >= steps // 5 + 1
    assert shapes == {first.shape}  # one size for every frame, whatever the caption says
    # 72 rows of scene under a caption band, padded by the encoder to a multiple of 16.
    assert first.shape[1] == 96 and first.shape[0] >= 72 + 2 * 18
    assert first[:20].mean() < first[50:].mean()  # the dark caption band sits on top


def run_copy(run_dir, out, frame):
    """A run directory at `out` with `run_dir`'s config and the records `frame`."""
    out.mkdir()
    (out / "config.yaml").write_text((run_dir / "config.yaml").read_text())
    frame.to_parquet(out / "episodes.parquet")
    return out


def test_a_record_that_disagrees_with_its_episode_is_reported_with_the_column(run, tmp_path):
    run_dir, records = run
    frame = records.copy()
    frame.loc[frame["method"] == "dp", "scooped"] += 1
    tampered = run_copy(run_dir, tmp_path / "tampered", frame)
    result = replay_episode(tampered, **episode(records, "dp"))
    assert not result.matches and list(result.mismatches) == ["scooped"]
    assert "DIVERGED" in result.describe() and "scooped" in result.describe()


def test_metrics_a_record_predates_are_measured_and_named_not_compared(run, tmp_path):
    run_dir, records = run
    older = run_copy(run_dir, tmp_path / "older", records.drop(columns=["transfer_ik_failures", "transfer_max_joint_step_rad"]))
    result = replay_episode(older, **episode(records, "dp"))
    assert result.matches, result.describe()
    row = records[records["method"] == "dp"].iloc[0]
    assert result.unrecorded == {"transfer_ik_failures": row["transfer_ik_failures"],
                                 "transfer_max_joint_step_rad": pytest.approx(row["transfer_max_joint_step_rad"], nan_ok=True)}
    assert "not in the record: transfer_ik_failures" in result.describe()
    assert "transfer_ik_failures" not in result.compared
    # A run resumed across the commit that added them holds the columns, empty in its older rows.
    resumed = records.copy()
    resumed["transfer_ik_failures"] = resumed["transfer_ik_failures"].astype(float)
    resumed.loc[resumed["method"] == "dp", "transfer_ik_failures"] = math.nan
    result = replay_episode(run_copy(run_dir, tmp_path / "resumed", resumed), **episode(records, "dp"))
    assert result.matches, result.describe()
    assert result.unrecorded == {"transfer_ik_failures": row["transfer_ik_failures"]}


def test_a_checkpoint_that_changed_since_the_record_stops_the_replay(run, tmp_path):
    run_dir, records = run
    frame = records.copy()
    frame["checkpoint_policy"] = "0" * 16
    changed = run_copy(run_dir, tmp_path / "changed", frame)
    with pytest.raises(StorageError, match="checkpoint `policy`.*digest"):
        replay_episode(changed, **episode(records, "dp"))


def test_an_episode_that_was_not_recorded_names_what_was(run):
    run_dir, records = run
    with pytest.raises(InputError, match="no record of method 'dp'.*trial 7"):
        replay_episode(run_dir, **{**episode(records, "dp"), "trial": 7})


def test_the_replay_command_prints_one_json_object_and_exits_0_on_a_match(run, capsys):
    run_dir, records = run
    e = episode(records, "grits")
    code = main(["replay", str(run_dir), "--method", "grits", "--food", e["food"], "--level", e["level"], "--trial", "0", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["matches"] is True and out["seed"] == int(records["seed"].iloc[0])
    assert main(["replay", str(run_dir), "--method", "dp", "--food", e["food"], "--level", e["level"], "--trial", "0", "--video", "x.avi"]) == 2



def test_report_videos_replay_dp_beside_grits_on_the_same_seed(run, tmp_path):
    from functools import partial

    from grits_lab.report import build_report

    run_dir, records = run
    out = tmp_path / "report"
    build_report(run_dir, out, videos=1, replay=partial(replay_episode, camera=SMALL_CAMERA, every=5))
    html = (out / "report.html").read_text()
    sources = re.findall(r'<video [^>]*src="([^"]+)"', html)
    e = episode(records, "dp")
    assert sources == [f"videos/{e['food']}-{e['level']}-0-dp.mp4", f"videos/{e['food']}-{e['level']}-0-grits.mp4"]
    assert all((out / s).stat().st_size > 0 for s in sources)
    assert html.count("replay reproduces the record") == 2


def test_report_videos_need_an_evaluation_run_directory(tmp_path, capsys):
    records = tmp_path / "only-records"
    records.mkdir()
    pd.DataFrame([{"method": "dp", "food": "sago", "level": "low", "task_success": True, "spillage": False,
                   "scoop_failure": False}]).to_parquet(records / "episodes.parquet")
    assert main(["report", str(records), "--video-episodes", "1"]) == 2
    assert "lacks config.yaml" in capsys.readouterr().err


def test_a_replay_draws_a_guided_plan_over_its_cloud(run, tmp_path, capsys):
    run_dir, records = run
    picked = episode(records, "grits")
    result = replay_episode(run_dir, **picked, plan_figure=tmp_path / "plan.png")
    assert result.matches, result.describe()
    image = imageio.imread(tmp_path / "plan.png")
    assert image.shape[0] > 200 and image.shape[1] > 400 and image.std() > 0
    # dp has no guidance to draw: one clear error, before any figure.
    code = main(["replay", str(run_dir), "--method", "dp", "--food", picked["food"], "--level", picked["level"],
                 "--trial", str(picked["trial"]), "--plan-figure", str(tmp_path / "dp.png")])
    assert code == 2 and "no guidance to draw" in capsys.readouterr().err and not (tmp_path / "dp.png").exists()


def test_replaying_a_built_in_method_never_imports_the_lab_files_a_run_config_names(run, tmp_path):
    import yaml

    run_dir, records = run
    marker = tmp_path / "ran"
    lab = tmp_path / "lab.py"
    lab.write_text(f"import pathlib\npathlib.Path({str(marker)!r}).touch()\nclass C:\n    cloud_steps = 1\n    def reset(self, scene): pass\n    def plan(self, history, scene): return None\n")
    copied = run_copy(run_dir, tmp_path / "copied", records)
    config = yaml.safe_load((copied / "config.yaml").read_text())
    config["methods"] = [*config["methods"], "lab"]
    config["custom_methods"] = {"lab": {"controller": f"{lab}:C"}}
    (copied / "config.yaml").write_text(yaml.safe_dump(config))
    result = replay_episode(copied, **episode(records, "dp"))
    assert result.matches, result.describe()
    assert not marker.exists()


def test_a_planted_checkpoint_with_its_digest_in_the_records_is_refused_and_never_runs(run, tmp_path, plant_pickle):
    import yaml

    from grits_lab.evaluation.methods import file_digest

    run_dir, records = run
    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    planted = tmp_path / "policy.pt"
    marker = plant_pickle(config["checkpoints"]["policy"], planted)
    frame = records.copy()
    frame["checkpoint_policy"] = file_digest(planted)  # whoever can write the run directory can write its records
    copied = run_copy(run_dir, tmp_path / "copied", frame)
    config["checkpoints"]["policy"] = str(planted)
    (copied / "config.yaml").write_text(yaml.safe_dump(config))
    with pytest.raises(InputError, match=f"refused checkpoint {planted}"):
        replay_episode(copied, **episode(records, "dp"))
    assert not marker.exists()


def test_the_filmed_and_counted_envs_see_the_actions_of_the_smooth_stages_too():
    """The stages after the scoop step through `ScoopEnv.step_along`: a replay films and counts those actions."""
    import numpy as np

    from grits_lab.report.replay import _CountedEnv, _FilmedEnv
    from grits_lab.sim import ScoopEnv
    from grits_lab.sim.env import matrix_to_pose9

    env = ScoopEnv()
    try:
        ticks = []
        filmed = _FilmedEnv(env, "title", SMALL_CAMERA, every=1)
        played = _CountedEnv(filmed, lambda: ticks.append(1))
        played.reset(seed=0, options={"food": "soybeans", "n_particles": 0})
        pose = matrix_to_pose9(env.pose_target)
        played.step(pose)
        played.step_along(np.stack([pose, pose]))
        assert len(filmed.frames) == 3 and len(ticks) == 2  # the reset's frame, then one per action
    finally:
        env.close()


def test_a_diverged_replay_names_the_cpu_kernels_of_record_and_replay(run, tmp_path):
    run_dir, records = run
    dp = records["method"] == "dp"
    recorded = str(records.loc[dp, "cpu_kernels"].iloc[0])
    assert recorded.startswith("numpy ") and "torch " in recorded  # the worker ran a network
    frame = records.copy()
    frame.loc[dp, "scooped"] += 1
    same = replay_episode(run_copy(run_dir, tmp_path / "same", frame), **episode(records, "dp"))
    assert same.recorded_kernels == same.replayed_kernels == recorded
    assert "kernels" not in same.describe()  # a divergence on the same kernels is the code's or the record's
    elsewhere = "numpy baseline; openblas Prescott; torch DEFAULT"  # kernels no machine that runs the suite reports
    assert elsewhere != recorded
    frame.loc[dp, "cpu_kernels"] = elsewhere
    other = replay_episode(run_copy(run_dir, tmp_path / "other", frame), **episode(records, "dp"))
    assert list(other.mismatches) == ["scooped"]  # the label itself is never compared
    assert f"recorded on CPU kernels `{elsewhere}`, replayed on `{recorded}`" in other.describe()
    older = replay_episode(run_copy(run_dir, tmp_path / "older", frame.drop(columns=["cpu_kernels"])), **episode(records, "dp"))
    assert "the record does not name its CPU kernels" in older.describe() and "cpu_kernels" not in older.unrecorded


def test_a_video_destination_that_cannot_be_written_is_refused_before_the_replay(run, tmp_path, capsys, monkeypatch):
    from grits_lab.sim import env as sim_env

    run_dir, records = run
    e = episode(records, "dp")
    (tmp_path / "a_file").write_text("")
    target = tmp_path / "a_file" / "dp.gif"

    def no_world(*args, **kwargs):
        raise AssertionError("the world was built before the destination was checked")

    monkeypatch.setattr(sim_env, "ScoopEnv", no_world)
    code = main(["replay", str(run_dir), "--method", "dp", "--food", e["food"], "--level", e["level"], "--trial", "0", "--video", str(target)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and f"cannot write {target}: {tmp_path / 'a_file'} is not a directory" in err[0], err
