"""`grits-lab dataset export`: a collected demonstration dataset loaded back by zarr and by lerobot.

Each round trip loads the export with that library as its users do (diffusion_policy's
ReplayBuffer reads `data/*` and `meta/episode_ends` from the zarr group; lerobot's
`LeRobotDataset(repo_id, root=...)`) and compares every step's observations and actions with the
episode files. lerobot pins a torch older than this project's CPU build, so its test runs where
lerobot is installed (a separate environment) and is skipped elsewhere with the reason.
"""

import json

import numpy as np
import pytest
import yaml

from grits_lab.cli import main
from grits_lab.cli.dataset_export import FORMATS
from grits_lab.collection.demos import DemosConfig
from grits_lab.collection.jobs import run_collection
from grits_lab.config import config_from_dict
from grits_lab.data.export import EXPORT_FORMATS, LEROBOT_KEYS
from grits_lab.data.format import MANIFEST_FILE, load_index, read_episode

CAMERAS = [{"name": "front", "eye": [1.05, -0.15, 0.55], "target": [0.5, -0.1, 0.03], "width": 64, "height": 48}]


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    """Two real expert demonstrations (two quantity levels), with clouds and one small RGB-D camera."""
    out = tmp_path_factory.mktemp("export") / "demos"
    config = config_from_dict(DemosConfig, {
        "output_dir": str(out), "foods": ["dried_jujube"], "levels": ["low", "medium"], "bowl_configs": 1,
        "cloud": {"n_points": 64, "cad_surface_samples": 1000}, "sim": {"cameras": CAMERAS},
        "images": {"enabled": True, "height": 12, "width": 16}, "executor": {"backend": "serial"},
    })
    assert run_collection(config, progress=False)["episodes"] == 2
    return out


def originals(dataset):
    index = load_index(dataset).sort_values("episode_id")
    return [(row.episode_id, row.food, row.level, read_episode(dataset / row.file)[0]) for row in index.itertuples()]


def test_cli_and_exporter_offer_the_same_formats():
    assert FORMATS == EXPORT_FORMATS


def test_zarr_export_loads_as_a_diffusion_policy_replay_buffer(demos, tmp_path, capsys):
    zarr = pytest.importorskip("zarr", reason="the zarr extra is not installed (pip install \"grits-lab[zarr]\")")
    out = tmp_path / "demos.zarr"
    assert main(["dataset", "export", str(demos), "--format", "zarr", "--output", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    episodes = originals(demos)
    assert summary["episodes"] == 2 and summary["frames"] == sum(len(a["action"]) for *_, a in episodes)
    root = zarr.open_group(str(out), mode="r")
    assert root.metadata.zarr_format == 2  # diffusion_policy pins zarr 2
    ends = root["meta"]["episode_ends"][:]
    assert ends.dtype == np.int64
    np.testing.assert_array_equal(ends, np.cumsum([len(a["action"]) for *_, a in episodes]))
    assert sorted(root["data"].array_keys()) == sorted(episodes[0][3])
    starts = np.concatenate([[0], ends[:-1]])
    for (episode_id, food, level, arrays), start, end in zip(episodes, starts, ends):
        for key, value in arrays.items():
            stored = root["data"][key][start:end]
            assert stored.dtype == value.dtype
            np.testing.assert_array_equal(stored, value, err_msg=f"{episode_id} {key}")
    assert root.attrs["episode_ids"] == [e for e, *_ in episodes]
    assert root.attrs["level"] == ["low", "medium"] and root.attrs["fps"] == 10.0


def test_lerobot_export_loads_as_a_lerobot_dataset(demos, tmp_path):
    pytest.importorskip("lerobot.datasets.lerobot_dataset",
                        reason="lerobot is not installed: it pins torch<2.11, so it lives in its own environment "
                               "(pip install \"grits-lab[lerobot]\" there)")
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    out = tmp_path / "lerobot"
    assert main(["dataset", "export", str(demos), "--format", "lerobot", "--output", str(out), "--repo-id", "lab/demos"]) == 0
    loaded = LeRobotDataset("lab/demos", root=out)
    episodes = originals(demos)
    assert loaded.num_episodes == 2 and loaded.fps == 10
    assert loaded.num_frames == sum(len(a["action"]) for *_, a in episodes)
    index = 0
    for episode_index, (episode_id, food, level, arrays) in enumerate(episodes):
        for t in range(len(arrays["action"])):
            frame = loaded[index]
            assert int(frame["episode_index"]) == episode_index and int(frame["frame_index"]) == t
            assert frame["task"] == f"scoop {level} {food}"
            for key, value in arrays.items():
                got = frame[LEROBOT_KEYS[key]].numpy()
                want = value[t].astype(got.dtype).reshape(got.shape)
                np.testing.assert_array_equal(got, want, err_msg=f"{episode_id} step {t} {key}")
            index += 1
    assert json.loads((out / "meta" / "grits_lab.json").read_text())["episode_ids"] == [e for e, *_ in episodes]


def test_export_refuses_a_spillage_dataset_and_an_existing_output(tmp_path, capsys):
    (tmp_path / "trials").mkdir()
    (tmp_path / "trials" / MANIFEST_FILE).write_text(yaml.safe_dump({"kind": "spillage"}))
    assert main(["dataset", "export", str(tmp_path / "trials"), "--format", "zarr", "--output", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "only demonstration datasets (kind: demos)" in err and err.count("\n") == 1
    (tmp_path / "trials" / MANIFEST_FILE).write_text(yaml.safe_dump({"kind": "demos"}))
    (tmp_path / "o").mkdir()
    assert main(["dataset", "export", str(tmp_path / "trials"), "--format", "zarr", "--output", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"--output {tmp_path / 'o'} already exists" in err and err.count("\n") == 1
