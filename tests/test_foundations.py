"""Rotation conversions, derived seeds, atomic writes and the episode file format."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from grits_lab.data.format import load_index, read_episode, rebuild_index, write_episode
from grits_lab.errors import StorageError
from grits_lab.geometry import (
    axis_angle_matrix,
    cubic_pose_path,
    matrix_to_rot6d,
    pose7_to_pose9,
    pose9_to_pose7,
    quat_to_matrix,
    rot6d_to_matrix,
)
from grits_lab.io import ensure_writable_dir, write_text_atomic
from grits_lab.seeding import derive_seed


def _random_quats(n, seed=0):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0] *= -1
    return q


def test_pose_round_trip_and_orthonormality():
    pose7 = np.concatenate([np.random.default_rng(1).normal(size=(50, 3)), _random_quats(50)], axis=1)
    np.testing.assert_allclose(pose9_to_pose7(pose7_to_pose9(pose7)), pose7, atol=1e-9)
    m = quat_to_matrix(pose7[:, 3:])
    np.testing.assert_allclose(m @ np.swapaxes(m, 1, 2), np.broadcast_to(np.eye(3), m.shape), atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-9)


def test_rot6d_projects_noisy_vectors_to_rotations():
    noisy = matrix_to_rot6d(quat_to_matrix(_random_quats(20))) + 0.1 * np.random.default_rng(2).normal(size=(20, 6))
    m = rot6d_to_matrix(noisy)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-9)
    # the first column keeps the direction of the first three numbers
    cos = np.sum(m[:, :, 0] * noisy[:, :3], axis=1) / np.linalg.norm(noisy[:, :3], axis=1)
    np.testing.assert_allclose(cos, 1.0, atol=1e-9)


def _spline_waypoints() -> tuple[np.ndarray, np.ndarray]:
    """A start and 8 waypoints that move, turn about z and stop: (9,), (8, 9)."""
    turns = axis_angle_matrix([0.0, 0.0, 1.0], np.radians([0, 5, 15, 30, 45, 55, 60, 60, 60]))
    xyz = np.array([[0, 0, 0], [0.01, 0, 0], [0.03, 0.01, 0], [0.06, 0.03, 0.01], [0.08, 0.06, 0.02],
                    [0.09, 0.08, 0.02], [0.09, 0.09, 0.02], [0.09, 0.09, 0.02], [0.09, 0.09, 0.02]], dtype=float)
    poses = np.concatenate([xyz, matrix_to_rot6d(turns)], axis=1)
    return poses[0], poses[1:]


def test_the_cubic_pose_path_passes_every_waypoint_with_continuous_velocity():
    start, waypoints = _spline_waypoints()
    path = cubic_pose_path(start, waypoints, 12)
    assert path.shape == (8, 12, 9)
    np.testing.assert_allclose(path[:, -1], waypoints, atol=1e-12)  # each span ends on its waypoint
    m = rot6d_to_matrix(path[..., 3:])
    np.testing.assert_allclose(m @ np.swapaxes(m, -1, -2), np.broadcast_to(np.eye(3), m.shape), atol=1e-9)
    dense = np.concatenate([start[None], path.reshape(-1, 9)])
    velocity = np.diff(dense, axis=0) * 12  # per span, so a straight span's velocity is its length
    # At every waypoint the velocity just before equals the velocity just after, to the
    # spline's curvature over one piece; straight spans jump there by the change of span.
    after_knot, before_knot = velocity[12::12], velocity[11:-1:12]
    jumps = np.abs(after_knot - before_knot)[:, :3].max()
    straight = np.abs(np.diff(np.diff(np.concatenate([start[None], waypoints]), axis=0), axis=0))[:, :3].max()
    assert jumps < 0.2 * straight
    # From rest and to rest: the first and last pieces move far less than an average piece.
    assert np.linalg.norm(velocity[0, :3]) < 0.1 * np.linalg.norm(waypoints[1, :3] - waypoints[0, :3])
    np.testing.assert_allclose(path[-1], np.broadcast_to(waypoints[-1], (12, 9)), atol=1e-12)  # held still: no drift


def test_the_cubic_pose_path_of_a_steady_line_is_the_line():
    start = np.array([0, 0, 0, 1, 0, 0, 0, 1, 0], dtype=float)
    waypoints = np.stack([start + [0.01 * k, 0, 0, 0, 0, 0, 0, 0, 0] for k in range(1, 7)])
    path = cubic_pose_path(start, waypoints, 4)
    np.testing.assert_allclose(np.diff(path[1:-1].reshape(-1, 9)[:, 0]), 0.0025, atol=1e-12)  # inside: constant speed
    with pytest.raises(ValueError, match="pieces >= 1"):
        cubic_pose_path(start, waypoints, 0)
    with pytest.raises(ValueError, match="waypoints"):
        cubic_pose_path(start, waypoints[:, :7], 4)


def test_derived_seeds_are_stable_and_distinct():
    assert derive_seed(0, "sago", "low", 3) == derive_seed(0, "sago", "low", 3)
    seeds = {derive_seed(0, food, level, i) for food in ("sago", "penne") for level in ("low", "high") for i in range(50)}
    assert len(seeds) == 200
    assert derive_seed(1, "sago", "low", 3) != derive_seed(0, "sago", "low", 3)
    assert 0 <= derive_seed(123, "x") < 2**31


def test_episode_round_trip_and_index(tmp_path):
    traj = np.arange(27, dtype=np.float32).reshape(3, 9)
    write_episode(tmp_path, "ep_000001", {"trajectory": traj}, {"food": "sago", "label": 1})
    write_episode(tmp_path, "ep_000000", {"trajectory": traj * 2}, {"food": "penne", "label": 0})
    arrays, meta = read_episode(tmp_path / "episodes" / "ep_000001.npz")
    np.testing.assert_array_equal(arrays["trajectory"], traj)
    assert meta["food"] == "sago" and meta["episode_id"] == "ep_000001"
    index = rebuild_index(tmp_path)
    assert list(index["episode_id"]) == ["ep_000000", "ep_000001"]
    assert not [p for p in (tmp_path / "episodes").iterdir() if p.name.startswith(".")]


def test_a_damaged_index_is_rebuilt_from_the_episode_files(tmp_path):
    write_episode(tmp_path, "ep_a", {"x": np.zeros(3)}, {"food": "sago"})
    rebuild_index(tmp_path)
    (tmp_path / "index.parquet").write_bytes(b"not parquet")
    index = load_index(tmp_path)
    assert list(index["food"]) == ["sago"]
    assert list(pd.read_parquet(tmp_path / "index.parquet")["food"]) == ["sago"]  # written again, whole


def test_corrupted_episode_is_detected(tmp_path):
    write_episode(tmp_path, "ep_a", {"x": np.zeros(3)}, {})
    path = tmp_path / "episodes" / "ep_a.npz"
    path.write_bytes(path.read_bytes()[:40])
    with pytest.raises(StorageError, match="corrupted or unreadable episode file"):
        read_episode(path)
    assert rebuild_index(tmp_path, on_corrupt="skip").empty


def _unwritable_dir(tmp_path):
    """A directory nobody may write to: /sys refuses even root; chmod works for other users."""
    if os.geteuid() == 0:
        return Path("/sys/grits_lab_unwritable")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    return locked / "sub"


def test_unwritable_directory_gives_clear_error(tmp_path):
    target = _unwritable_dir(tmp_path)
    with pytest.raises(StorageError, match="permission denied or read-only"):
        ensure_writable_dir(target)
    with pytest.raises(StorageError, match="cannot write"):
        write_text_atomic(target / "f.txt", "x")


def test_a_full_disk_is_one_clear_error_and_leaves_the_previous_file_intact(tmp_path, full_disk):
    target = tmp_path / "summary.json"
    target.write_text("previous")
    with pytest.raises(StorageError, match=f"no space left on device while writing {target}"):
        write_text_atomic(target, "new contents")
    assert target.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]  # no temporary file left behind
    with pytest.raises(StorageError, match="no space left on device"):
        write_episode(tmp_path, "ep_a", {"x": np.zeros(3)}, {})
    assert not (tmp_path / "episodes" / "ep_a.npz").exists()


def test_atomic_writes_get_the_mode_an_ordinary_write_gets(tmp_path):
    old = os.umask(0o027)  # a group-shared results disk
    try:
        write_text_atomic(tmp_path / "report.html", "<html/>")
        with open(tmp_path / "plain.txt", "w") as fh:
            fh.write("x")
    finally:
        os.umask(old)
    mode = lambda p: p.stat().st_mode & 0o777  # noqa: E731
    assert mode(tmp_path / "report.html") == mode(tmp_path / "plain.txt") == 0o640
    # an existing file keeps its mode, as it does under an ordinary write
    os.chmod(tmp_path / "report.html", 0o664)
    write_text_atomic(tmp_path / "report.html", "<html>again</html>")
    assert mode(tmp_path / "report.html") == 0o664


def test_one_writer_per_directory_a_second_is_refused_naming_the_first(tmp_path, hold_directory):
    from grits_lab.io import exclusive_directory

    holder = hold_directory(tmp_path, "collect")
    with pytest.raises(StorageError) as refused:
        with exclusive_directory(tmp_path, "evaluate"):
            pass
    assert f"is being written by `grits-lab collect` (pid {holder.pid} on " in str(refused.value)
    assert "\n" not in str(refused.value)


def test_a_lock_its_holder_left_behind_is_taken_over_with_one_line(tmp_path, capsys):
    import json
    import socket

    from grits_lab.io import LOCK_FILE, exclusive_directory

    (tmp_path / LOCK_FILE).write_text(json.dumps({"pid": 2 ** 22 + 7, "host": socket.gethostname(), "command": "train policy", "started": "x"}))
    with exclusive_directory(tmp_path, "train policy"):
        held = json.loads((tmp_path / LOCK_FILE).read_text())
    assert held["pid"] == os.getpid()
    assert (tmp_path / LOCK_FILE).read_text() == ""  # released
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"taking over {tmp_path / LOCK_FILE} from `grits-lab train policy` (pid {2 ** 22 + 7}" in err[0]
    with exclusive_directory(tmp_path, "evaluate"):  # a released lock: taken without a word
        pass
    assert capsys.readouterr().err == ""


def test_a_markdown_table_aligns_its_columns_and_refuses_a_ragged_row():
    from grits_lab.markdown import markdown_table

    table = markdown_table(["Method", "Stage", "n"], [["DP", "carry", "3"]], right=2)
    assert table.splitlines() == ["| Method | Stage | n |", "|---|---|---:|", "| DP | carry | 3 |"]
    with pytest.raises(ValueError, match="2 cells, the header 3"):
        markdown_table(["Method", "Stage", "n"], [["DP", "carry"]])


def test_error_text_is_empty_where_an_episode_raised_nothing_whatever_the_stored_dtype():
    import warnings

    from grits_lab.records import error_text

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an all-null float column must not take the deprecated string fill
        assert error_text(pd.Series([np.nan, np.nan])).tolist() == ["", ""]
    assert error_text(pd.Series(["InputError: x", None])).tolist() == ["InputError: x", ""]
    assert error_text(pd.Series(["boom", pd.NA], dtype="string")).tolist() == ["boom", ""]


def test_evaluate_and_the_report_count_the_same_episodes_as_failed():
    # one rule for a failed episode: text other than whitespace in `error`, whatever the stored dtype
    from grits_lab.records import OUTCOME_COLUMNS, has_error
    from grits_lab.report.run_records import normalize_records

    errors = ["InputError: heap outside the bowl", None, "   ", "\n", np.nan, " RuntimeError: x "]
    assert has_error(pd.Series(errors)).tolist() == [True, False, False, False, False, True]
    frame = pd.DataFrame({"method": "dp", "food": "sago", "level": "brim", "error": errors,
                          **{c: False for c in OUTCOME_COLUMNS}})
    report = normalize_records(frame)
    assert report["is_error"].tolist() == has_error(pd.Series(errors)).tolist()
    assert report["error"].tolist()[-1] == "RuntimeError: x"
