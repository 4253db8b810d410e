"""`grits-lab rollout / scene / foods`: JSON output and one-line errors with exit code 2 on bad input."""

from __future__ import annotations

import json

import numpy as np

from grits_lab.sim.foods import load_foods
import pytest

from grits_lab.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(code, err, *needles):
    assert code == 2
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("pybullet build time")]
    assert len(lines) == 1 and lines[0].startswith("grits-lab: error:"), err
    for needle in needles:
        assert needle in lines[0]


def test_foods_json_lists_all_foods(capsys):
    code, out, _ = run(capsys, "foods", "--json", "--no-settle")
    data = json.loads(out)
    assert code == 0 and len(data["foods"]) == 16
    orange = next(f for f in data["foods"] if f["food"] == "orange")
    assert orange["split"] == "train" and len(orange["levels"]) == 1


def test_scene_json_has_the_geometry(capsys):
    code, out, _ = run(capsys, "scene", "--episode-seed", "4", "--json")
    scene = json.loads(out)
    assert code == 0 and scene["seed"] == 4
    assert scene["source_bowl_rim_height"] == pytest.approx(0.065) and len(scene["cameras"]) == 2
    assert len(scene["target_bowl_position"]) == 3 and "bowl_length" in scene["spoon"]


@pytest.mark.parametrize("argv, needles", [
    (["--food", "pizza", "--level", "low"], ["unknown food", "pizza"]),
    (["--food", "orange", "--level", "low"], ["quantity level", "low"]),
])
def test_unknown_food_or_level(capsys, argv, needles):
    code, _, err = run(capsys, "rollout", *argv, "--episode-seed", "0", "--expert")
    assert_one_line_error(code, err, *needles)


@pytest.mark.parametrize("array, needle", [
    (np.zeros((10, 5)), "shape"),
    (np.zeros(9), "shape"),
    (np.full((4, 9), np.nan), "NaN"),
])
def test_bad_trajectories(capsys, tmp_path, array, needle):
    path = tmp_path / "traj.npy"
    np.save(path, array)
    code, _, err = run(capsys, "rollout", "--food", "orange", "--level", "medium", "--episode-seed", "0", "--trajectory", str(path))
    assert_one_line_error(code, err, needle)


def test_missing_trajectory_file(capsys, tmp_path):
    code, _, err = run(capsys, "rollout", "--food", "orange", "--level", "medium", "--episode-seed", "0", "--trajectory", str(tmp_path / "no.npy"))
    assert_one_line_error(code, err, "not found")


def test_food_file_with_negative_mass(capsys, tmp_path):
    path = tmp_path / "foods.yaml"
    path.write_text("foods:\n  peas:\n    split: train\n    levels: {low: {pieces: 5}}\n    components:\n"
                    "      - {shape: sphere, radius: [0.004, 0.005], mass: [-0.001, 0.001]}\n")
    code, _, err = run(capsys, "foods", "--foods-file", str(path))
    assert_one_line_error(code, err, "peas", "mass")
    code, _, err = run(capsys, "rollout", "--food", "peas", "--level", "low", "--episode-seed", "0", "--expert", "--foods-file", str(path))
    assert_one_line_error(code, err, "peas", "mass")


def test_rollout_of_a_quaternion_trajectory_prints_one_json_record(capsys, tmp_path):
    # Hold the spoon near its home pose for 1 s, as (T, 7) xyz + quaternion.
    traj = np.tile(np.array([0.5, 0.0, 0.22, 0.0, 0.0, 0.0, 1.0]), (10, 1))
    path, saved = tmp_path / "hold.npy", tmp_path / "played.npy"
    np.save(path, traj)
    code, out, _ = run(capsys, "rollout", "--food", "orange", "--level", "medium", "--episode-seed", "2",
                       "--trajectory", str(path), "--json", "--save-trajectory", str(saved))
    assert code == 0
    record = json.loads(out)
    for key in ("food", "quantity", "seed", "n_particles", "spilled", "scooped", "spoon_coverage", "spillage",
                "scoop_failure", "scoop_success", "ik_failures"):
        assert key in record
    assert record["scoop_failure"] and record["spilled"] == 0 and record["n_particles"] == load_foods().get("orange").levels["medium"].pieces
    assert np.load(saved).shape == (10, 9)


def _check_level_bands(food: dict) -> None:
    """The documented bands (grits_lab/sim/foods.yaml): small-particle foods fill the bowl (inner
    depth 5.9 cm) to >= 40 % at the high level and >= 1 cm at the low level; large pieces lie in
    >= 2 layers at the high level."""
    levels = list(food["levels"].values())
    if food["success_rule"] == "coverage":
        assert levels[-1]["fill_height_m"] >= 0.4 * 0.059, food["food"]
        assert levels[0]["fill_height_m"] >= 0.01, food["food"]
    else:
        assert levels[-1]["layers"] >= 2.0, food["food"]
    for level in levels:
        assert level["fill_height_m"] < 0.065 and level["n_particles"] >= 1  # below the rim


def test_foods_json_gives_amount_count_and_settled_fill_height(capsys):
    code, out, _ = run(capsys, "foods", "--json", "--food", "mung_beans", "--food", "milk_tea", "--food", "mentos")
    data = json.loads(out)
    assert code == 0 and [f["food"] for f in data["foods"]] == ["mung_beans", "milk_tea", "mentos"]
    mung = data["foods"][0]
    assert mung["levels"]["high"]["amount"] == {"fill_height_m": 0.024} and mung["coarse_grain"] > 1
    assert data["foods"][2]["levels"]["high"]["amount"]["pieces"] == data["foods"][2]["levels"]["high"]["n_particles"]
    for food in data["foods"]:
        _check_level_bands(food)


@pytest.mark.slow
def test_every_food_meets_its_fill_band(capsys):
    code, out, _ = run(capsys, "foods", "--json")
    assert code == 0
    for food in json.loads(out)["foods"]:
        _check_level_bands(food)


@pytest.mark.parametrize("flag", ["--video", "--save-trajectory"])
def test_a_destination_that_cannot_be_written_is_refused_before_the_simulator_starts(capsys, tmp_path, flag):
    (tmp_path / "a_file").write_text("")
    target = tmp_path / "a_file" / ("out.gif" if flag == "--video" else "played.npy")
    code, _, err = run(capsys, "rollout", "--food", "orange", "--level", "medium", "--episode-seed", "2", "--expert", flag, str(target))
    assert_one_line_error(code, err, str(target), "is not a directory")
