"""CLI of the data area: bad configs and paths fail with one line naming the problem."""

import pytest

from grits_lab.cli import main


@pytest.mark.parametrize(
    "text, message",
    [
        ("kind: demo\n", "`kind` must be one of 'demos', 'spillage'"),
        ("kind: spillage\nepisodes: 10\n", "`episodes` must be a multiple of the number of shapes (4)"),
        ("kind: spillage\nshift: {x: -1}\n", "`shift.x` must be non-negative"),
        ("kind: demos\nbowl_config: 3\n", "unknown key `bowl_config`"),
        ("kind: demos\nexecutor: {workers: 0}\n", "`executor.workers` must be at least 1"),
    ],
)
def test_collect_rejects_bad_configs(tmp_path, capsys, text, message):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    assert main(["collect", str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_dataset_info_on_a_non_dataset(tmp_path, capsys):
    assert main(["dataset", "info", str(tmp_path)]) == 2
    assert "not a grits-lab dataset" in capsys.readouterr().err


def test_output_made_by_another_config_is_refused(tmp_path, capsys):
    from grits_lab.collection.driver import DatasetWriter

    DatasetWriter(tmp_path / "d", "spillage", {"seed": 0})
    path = tmp_path / "c.yaml"
    path.write_text(f"kind: spillage\noutput_dir: {tmp_path / 'd'}\n")
    assert main(["collect", str(path), "--serial"]) == 2
    assert "made with a different config" in capsys.readouterr().err


@pytest.mark.ray
@pytest.mark.parametrize("config", ["spillage_quick.yaml", "demos_quick.yaml"])
def test_collect_on_an_unreachable_ray_cluster_fails_fast_without_an_output(tmp_path, capsys, monkeypatch, config):
    import socket
    import time
    from pathlib import Path

    with socket.socket() as sock:  # a port where nothing listens
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    monkeypatch.setenv("RAY_ADDRESS", f"127.0.0.1:{port}")
    repo = Path(__file__).resolve().parents[2]
    start = time.monotonic()
    assert main(["collect", str(repo / "experiments" / config), "--output-dir", str(tmp_path / "x"), "--no-progress"]) == 2
    assert time.monotonic() - start < 30
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"cannot connect to the Ray cluster at 127.0.0.1:{port}" in err[0], err
    assert not (tmp_path / "x").exists()


def test_collect_refuses_a_quantity_level_no_food_has_before_writing(tmp_path, capsys):
    path = tmp_path / "c.yaml"
    path.write_text(f"kind: demos\nfoods: [soybeans]\nlevels: [low, medum]\noutput_dir: {tmp_path / 'd'}\n")
    assert main(["collect", str(path), "--serial"]) == 2
    err = capsys.readouterr().err
    assert "`levels`" in err and "'medum'" in err and err.count("\n") == 1
    assert not (tmp_path / "d").exists()


def test_dataset_info_sums_spills_by_stage_and_cause_and_the_expert_per_food_level(tmp_path):
    import numpy as np
    import yaml

    from grits_lab.data.format import MANIFEST_FILE, write_episode
    from grits_lab.data.info import dataset_summary

    (tmp_path / MANIFEST_FILE).write_text(yaml.safe_dump({"kind": "demos", "status": "complete"}))
    rows = [("soybeans", "low", True, 3, 0, 1), ("soybeans", "low", False, 0, 0, 0), ("sago", "high", True, 0, 4, 0)]
    for i, (food, level, ok, rim, spoon, flung) in enumerate(rows):
        write_episode(tmp_path, f"e{i}", {"action": np.zeros((2, 9), np.float32)}, {
            "food": food, "level": level, "scoop_success": ok, "spilled_any": rim + spoon + flung > 0,
            "spilled_scoop_over_rim": rim, "spilled_lift_off_spoon": spoon, "spilled_carry_posture_flip": flung,
            "spilled_pour_poured_outside": 0})
    summary = dataset_summary(tmp_path)
    assert summary["spills_by_stage_and_cause"] == {
        "scoop / over_rim": "3 particles (38%) in 1 episodes", "lift / off_spoon": "4 particles (50%) in 1 episodes",
        "carry / posture_flip": "1 particles (12%) in 1 episodes"}
    assert summary["by_food_level"] == {"sago/high": "scoop success 1/1, spilled 1/1", "soybeans/low": "scoop success 1/2, spilled 1/2"}
