"""Real collection on the simulator: episode contents, clouds where objects are, resume == uninterrupted."""

import zipfile

import numpy as np
import pytest

from grits_lab.config import config_from_dict
from grits_lab.collection.driver import DatasetWriter
from grits_lab.collection.demos import DemosConfig, plan_demos
from grits_lab.data.format import list_episode_files, load_index, read_episode
from grits_lab.collection.jobs import run_collection
from grits_lab.collection.spillage_trials import SpillageConfig, chunk_labels, expert_mean_trajectory
from grits_lab.data.trajectories import shift_trajectory
from grits_lab.runners import SerialExecutor
from grits_lab.runners.work import WorkerContext, execute_spec
from grits_lab.sim.shapes import BowlGeometry

SMALL_CAMERAS = [
    {"name": "front", "eye": [1.05, -0.15, 0.55], "target": [0.5, -0.1, 0.03], "width": 96, "height": 72},
    {"name": "side", "eye": [0.5, -0.75, 0.5], "target": [0.5, -0.05, 0.03], "width": 96, "height": 72},
]


def test_chunk_labels_mark_chunks_where_the_count_rises():
    counts = np.array([0, 0, 0, 1, 1, 1, 1, 3, 3])
    starts, spilled = chunk_labels(counts, 3)
    np.testing.assert_array_equal(starts, [0, 3, 6])
    np.testing.assert_array_equal(spilled, [False, True, True])  # chunk 1: count before it was 0
    starts, spilled = chunk_labels(np.array([2, 2, 2]), 2, spilled_before=2)
    np.testing.assert_array_equal(spilled, [False, False])


def test_shifts_keep_the_spoon_inside_the_bowl():
    config = SpillageConfig()
    base = expert_mean_trajectory(config)
    bowl = BowlGeometry()
    center = np.array([0.5, -0.15, 0.0])
    for shift in ([0.07, 0.05, -0.05], [-0.07, -0.05, -0.05], [0.0, 0.0, 0.05]):
        traj, scale = shift_trajectory(base, np.array(shift), center, bowl.inner_radius_at, bowl.depth, bowl.floor_thickness)
        rel = traj[:, :3] - center
        inside = rel[:, 2] < bowl.depth
        radial = np.linalg.norm(rel[inside, :2], axis=1)
        base_rel = base[:, :3] - center
        base_excess = np.max(np.linalg.norm(base_rel[:, :2], axis=1) - (bowl.inner_radius_at(base_rel[:, 2]) - 0.02))
        assert np.all(radial - (bowl.inner_radius_at(rel[inside, 2]) - 0.02) <= max(base_excess, 0) + 1e-6)
        base_below = max(0.0, bowl.floor_thickness + 0.005 - base_rel[:, 2].min())
        assert np.all(rel[inside, 2] >= bowl.floor_thickness + 0.005 - base_below - 1e-6)
        assert 0.0 <= scale <= 1.0
    # an upward shift is always feasible and applied in full
    _, scale = shift_trajectory(base, np.array([0.0, 0.0, 0.05]), center, bowl.inner_radius_at, bowl.depth, bowl.floor_thickness)
    assert scale == 1.0


def _short_spillage_config(tmp_path, **overrides):
    base = expert_mean_trajectory(SpillageConfig())[:26]
    np.save(tmp_path / "base.npy", base)
    data = {
        "kind": "spillage", "output_dir": str(tmp_path / "spill"), "episodes": 2, "spill_fraction": 0.0, "shapes": ["sphere"],
        "base_trajectory": str(tmp_path / "base.npy"), "particles": {"fill_height": [0.005, 0.005], "radius": [0.004, 0.006]},
        "cloud": {"n_points": 200, "cad_surface_samples": 2000}, "sim": {"cameras": SMALL_CAMERAS},
        "executor": {"backend": "serial"}, "exit": {"enabled": False},
    }
    data.update(overrides)
    return config_from_dict(SpillageConfig, data)


def test_spillage_trial_clouds_have_n_points_where_the_objects_are(tmp_path):
    from grits_lab.collection.jobs import base_trajectory
    from grits_lab.seeding import derive_seed, make_rng
    from grits_lab.sim.env import worker_env
    from grits_lab.sim.foods import ParticleRanges, fill_count, primitive_food
    from grits_lab.collection.spillage_trials import make_trial_spec, source_bowl_region

    config = _short_spillage_config(tmp_path)
    spec = make_trial_spec(config, base_trajectory(config), source_bowl_region(config), "sphere", 0)
    ctx = WorkerContext()
    try:
        result = execute_spec(spec, ctx)
        assert result.ok, result.traceback
        env = worker_env(ctx, spec.params["trial"].sim)  # the worker's simulator, kept for the next spec
        bowl = env.source_bowl_pose()
    finally:
        ctx.close()
    arrays, meta = result.payload["arrays"], result.payload["meta"]
    c = len(arrays["chunk_start"])
    assert c == 3 and arrays["trajectory"].shape == (26, 9)
    for key in ("chunk_cloud", "chunk_cloud_raw"):
        assert arrays[key].shape == (c, 3, 200, 3) and arrays[key].dtype == np.float16
    assert meta["label"] == int(arrays["chunk_spilled"].any()) and meta["n_action_steps"] == config.n_action_steps
    food, count = primitive_food("sphere", make_rng(derive_seed(spec.seed, "food")), ParticleRanges(radius=(0.004, 0.006), fill_height=(0.005, 0.005)))
    assert meta["n_particles"] == count == fill_count(food, 0.005)
    # the first cloud is taken before any motion: the food is in the source bowl
    first = arrays["chunk_cloud"][0].astype(np.float64)
    rel_food = first[0] - bowl[:3, 3]
    assert np.all(np.linalg.norm(rel_food[:, :2], axis=1) < 0.09) and np.all((rel_food[:, 2] > -0.01) & (rel_food[:, 2] < 0.08))
    rel_bowl = first[2] - bowl[:3, 3]
    assert np.all(np.linalg.norm(rel_bowl[:, :2], axis=1) < 0.09) and np.all((rel_bowl[:, 2] > -0.01) & (rel_bowl[:, 2] < 0.07))
    assert np.isfinite(arrays["chunk_cloud_raw"].astype(np.float64)).all()
    assert set(np.unique(arrays["chunk_start"] % 12)) == {0}


def test_resume_after_interruption_gives_the_uninterrupted_dataset(tmp_path, monkeypatch):
    config = _short_spillage_config(tmp_path)
    run_collection(config, progress=False)
    full = {p.name: read_episode(p) for p in list_episode_files(config.output_dir)}
    assert len(full) == 2

    class Interrupt(SerialExecutor):
        polls = 0

        def poll(self, timeout=None):
            if Interrupt.polls == 1:
                raise KeyboardInterrupt
            Interrupt.polls += 1
            return super().poll(timeout)

    second = _short_spillage_config(tmp_path, output_dir=str(tmp_path / "spill2"))
    import grits_lab.runners.executor_config as runner_config

    with monkeypatch.context() as m:  # the job is stopped (as by Ctrl-C) after its first episode
        m.setattr(runner_config, "make_executor", lambda cfg: Interrupt())
        with pytest.raises(KeyboardInterrupt):
            run_collection(second, progress=False)
    assert len(list_episode_files(second.output_dir)) == 1
    run_collection(second, progress=False)  # resumes
    resumed = {p.name: read_episode(p) for p in list_episode_files(second.output_dir)}
    assert sorted(resumed) == sorted(full)
    for name, (arrays, meta) in full.items():
        r_arrays, r_meta = resumed[name]
        assert r_meta == meta
        for key in arrays:
            np.testing.assert_array_equal(r_arrays[key], arrays[key])
    a, b = load_index(config.output_dir), load_index(second.output_dir)
    assert a.drop(columns="file").equals(b.drop(columns="file"))


def test_demo_episode_records_every_step(tmp_path):
    config = config_from_dict(DemosConfig, {
        "output_dir": str(tmp_path / "demos"), "foods": ["dried_jujube"], "levels": ["low"], "bowl_configs": 1,
        "cloud": {"n_points": 128, "cad_surface_samples": 1000}, "sim": {"cameras": SMALL_CAMERAS},
        "images": {"enabled": True, "height": 24, "width": 32}, "executor": {"backend": "serial"},
    })
    summary = run_collection(config, progress=False)
    assert summary["episodes"] == 1 and summary["failed"] == 0
    (path,) = list_episode_files(config.output_dir)
    arrays, meta = read_episode(path)
    t = meta["steps"]
    assert t > 40
    assert arrays["action"].shape == (t, 9) and arrays["ee_pose"].shape == (t, 9) and arrays["joint_pos"].shape == (t, 7)
    assert arrays["cloud"].shape == (t, 3, 128, 3) and arrays["cloud"].dtype == np.float16
    assert arrays["rgbd"].shape == (t, 2, 4, 24, 32)
    # the spoon follows the commanded poses: measured pose at t+1 is near the command at t
    err = np.linalg.norm(arrays["ee_pose"][1:, :3] - arrays["action"][:-1, :3], axis=1)
    assert np.median(err) < 0.02
    # the spoon cloud is centred near the measured spoon position (handle included, so loosely)
    spoon_centroid = arrays["cloud"][:, 1].astype(np.float64).mean(axis=1)
    assert np.median(np.linalg.norm(spoon_centroid - arrays["ee_pose"][:, :3], axis=1)) < 0.08
    for key in ("food", "split", "level", "seed", "bowl_config", "scoop_success", "spilled", "n_particles"):
        assert key in meta
    assert meta["food"] == "dried_jujube" and meta["split"] == "train"
    index = load_index(config.output_dir)
    assert list(index["episode_id"]) == ["dried_jujube-low-b0"]


def test_damaged_episode_file_is_reported_and_regenerated(tmp_path, capsys):
    config = _short_spillage_config(tmp_path)
    run_collection(config, progress=False)
    files = list_episode_files(config.output_dir)
    original = {p.name: read_episode(p) for p in files}
    victim = files[0]
    data = bytearray(victim.read_bytes())
    with zipfile.ZipFile(victim) as archive:  # the largest array: its compressed bytes, not a header
        largest = max(archive.infolist(), key=lambda info: info.compress_size)
    start = largest.header_offset + 30 + len(largest.filename.encode()) + len(largest.extra)
    middle = start + largest.compress_size // 2  # inside an array's compressed bytes: the metadata still reads
    data[middle:middle + 16] = bytes(16)
    victim.write_bytes(bytes(data))
    summary = run_collection(config, progress=False)
    assert "will be regenerated" in capsys.readouterr().err
    assert summary["wall_time_s_this_time"] > 0  # the regeneration is this run's work
    arrays, meta = read_episode(victim)
    assert meta == original[victim.name][1]
    for key, value in original[victim.name][0].items():
        np.testing.assert_array_equal(arrays[key], value)

    from grits_lab.data.info import dataset_summary

    assert dataset_summary(config.output_dir)["status"] == "complete"
    victim.unlink()  # a bucket is now one short of its target
    status = dataset_summary(config.output_dir)["status"]
    import re

    found = re.match(r"incomplete \((\w+)/(\d) has (\d+) of (\d+)", status)
    assert found and int(found[3]) == int(found[4]) - 1, status


def test_a_second_collector_on_one_dataset_is_refused_before_it_writes(tmp_path, hold_directory):
    from grits_lab.errors import StorageError

    config = _short_spillage_config(tmp_path)
    (tmp_path / "spill").mkdir()
    holder = hold_directory(tmp_path / "spill", "collect")
    with pytest.raises(StorageError, match=rf"spill is being written by `grits-lab collect` \(pid {holder.pid} on"):
        run_collection(config, progress=False)
    assert [p.name for p in (tmp_path / "spill").iterdir()] == [".grits-lab.lock"]


def test_a_base_trajectory_that_is_not_a_pose_array_is_refused_before_the_dataset_exists(tmp_path):
    from grits_lab.errors import InputError

    np.save(tmp_path / "objects.npy", np.array([{"a": 1}], dtype=object))
    config = _short_spillage_config(tmp_path, base_trajectory=str(tmp_path / "objects.npy"))
    with pytest.raises(InputError, match="objects.npy"):
        run_collection(config, progress=False)
    assert not (tmp_path / "spill").exists()


def test_a_dataset_of_another_protocol_is_refused_and_a_new_one_names_its_own(tmp_path):
    import yaml

    from grits_lab.data.info import dataset_summary
    from grits_lab.errors import StorageError
    from grits_lab.versions import PROTOCOL

    config = _short_spillage_config(tmp_path, episodes=1)
    run_collection(config, progress=False)
    manifest_path = tmp_path / "spill" / "dataset.yaml"
    manifest = yaml.safe_load(manifest_path.read_text())
    assert manifest["protocol"] == PROTOCOL == dataset_summary(tmp_path / "spill")["protocol"]
    manifest_path.write_text(yaml.safe_dump({**manifest, "protocol": "scoop-v3"}, sort_keys=False))
    with pytest.raises(StorageError, match=rf"holds a dataset of protocol scoop-v3, but this code runs {PROTOCOL}"):
        run_collection(config, progress=False)


def _carry_config(tmp_path, **overrides):
    data = {
        "kind": "spillage", "output_dir": str(tmp_path / "carry"), "episodes": 2, "spill_fraction": 0.0, "shapes": ["sphere"],
        "balance_on": "horizon", "particles": {"fill_height": [0.012, 0.012], "radius": [0.006, 0.008]},
        "cloud": {"n_points": 128, "cad_surface_samples": 1000}, "sim": {"cameras": SMALL_CAMERAS},
        "executor": {"backend": "serial"}, "exit": {"kind": "carry"}, "raw_cloud": False,
    }
    data.update(overrides)
    return config_from_dict(SpillageConfig, data)


def test_a_carry_collection_stores_both_labels_and_the_carry_stages(tmp_path):
    from grits_lab.data.info import dataset_summary
    from grits_lab.evaluation.carry import carry_to_target

    config = _carry_config(tmp_path)
    summary = run_collection(config, progress=False, carry=carry_to_target)
    assert summary["episodes"] == 2 and summary["balanced_on"] == "horizon"
    episodes = [read_episode(p) for p in list_episode_files(config.output_dir)]
    carried = 0
    for arrays, meta in episodes:
        c = len(arrays["chunk_start"])
        assert arrays["chunk_spilled"].shape == arrays["chunk_spilled_horizon"].shape == (c,)
        assert meta["exit_kind"] == "carry" and meta["label_horizon"] == 0  # the no-spill bucket of the horizon label
        assert len(arrays["spilled_until_delivery"]) == meta["steps"] + meta["carry_steps"]
        np.testing.assert_array_equal(arrays["spilled_until_delivery"][: meta["steps"]], arrays["spilled_over_time"])
        if meta["scooped"] > 0:  # a load was lifted: the evaluation's transfer and pour took it to the target bowl
            carried += 1
            assert meta["carry_steps"] > 30 and meta["carry_plan"].startswith("level over")
            assert {f"spilled_after_{stage}" for stage in ("lift", "carry", "pour", "after_pour")} <= set(meta)
    assert carried >= 1
    info = dataset_summary(config.output_dir)
    assert info["mean_label"] == 0.0 and info["mean_label_horizon"] == 0.0
    assert info["chunks"] == sum(len(a["chunk_start"]) for a, _ in episodes) and info["chunk_rate_horizon"] == 0.0
    assert info["by_shape_label"] == {"sphere/0": 2} and info["status"] == "complete"


def test_a_carry_collection_without_the_carry_runner_is_refused_before_the_dataset_exists(tmp_path):
    from grits_lab.errors import ConfigError

    with pytest.raises(ConfigError, match=r"`exit.kind` is carry, but no carry runner"):
        run_collection(_carry_config(tmp_path), progress=False)
    assert not (tmp_path / "carry").exists()


@pytest.mark.parametrize("override, key", [
    ({"exit": {"kind": "teleport"}}, "exit.kind"),
    ({"exit": {"kind": "carry", "transfer": {"clearance": -0.01}}}, "exit.transfer.clearance"),
    ({"exit": {"kind": "carry", "tilt_deg": [10, 20]}}, "exit.tilt_deg"),
    ({"balance_on": "future"}, "balance_on"),
])
def test_carry_and_label_config_errors_name_the_key(tmp_path, override, key):
    from grits_lab.errors import ConfigError

    with pytest.raises(ConfigError, match=rf"^`{key}`"):
        _carry_config(tmp_path, **override)


def test_a_lift_and_exit_config_keeps_the_fingerprint_of_datasets_made_before_the_carry():
    identity = config_from_dict(SpillageConfig, {"exit": {"kind": "exit"}}).identity()
    assert "balance_on" not in identity and not {"kind", "transfer"} & set(identity["exit"])
    carry = config_from_dict(SpillageConfig, {"balance_on": "horizon"}).identity()
    assert carry["exit"]["kind"] == "carry" and carry["balance_on"] == "horizon" and carry["exit"]["transfer"]["max_speed"] == 0.12


def _probe_specs(n, fail):
    from grits_lab.runners import EpisodeSpec, probe_episode

    return [EpisodeSpec(episode_id=f"ep{i:03d}", work=probe_episode, seed=100 + i, params={"fail": i in fail}) for i in range(n)]


def test_a_job_whose_every_episode_failed_stops_with_the_first_error(tmp_path):
    from grits_lab.collection.driver import run_fixed_job
    from grits_lab.errors import JobError

    writer = DatasetWriter(tmp_path / "ds", "demos", {"probe": 1})
    with SerialExecutor() as ex, pytest.raises(JobError) as err:
        run_fixed_job(ex, writer, _probe_specs(3, fail={0, 1, 2}), desc="demos", progress=False)
    msg = str(err.value)
    assert msg.startswith("demos: every episode failed (3); the first with ValueError: probe episode ep000 asked to fail")
    assert str(tmp_path / "ds" / "failures") in msg
    assert len(writer.failures()) == 3  # the tracebacks stay on disk for the user to read


def test_a_job_with_some_failed_episodes_goes_on_and_counts_them(tmp_path):
    from grits_lab.collection.driver import run_fixed_job

    config = config_from_dict(DemosConfig, {
        "output_dir": str(tmp_path / "demos"), "foods": ["dried_jujube"], "levels": ["low"], "bowl_configs": 1,
        "cloud": {"n_points": 64, "cad_surface_samples": 500}, "executor": {"backend": "serial"},
    })
    specs = plan_demos(config) + _probe_specs(1, fail={0})
    writer = DatasetWriter(config.output_dir, "demos", {"probe": 1})
    with SerialExecutor() as ex:
        summary = run_fixed_job(ex, writer, specs, desc="demos", progress=False)
    assert summary["episodes"] == 1 and summary["failed"] == 1 and summary["requested"] == 2
    assert [f["episode_id"] for f in writer.failures()] == ["ep000"]
