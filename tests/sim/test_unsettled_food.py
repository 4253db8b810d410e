"""A food whose particles do not all come to rest inside the source bowl is refused at reset, never
scored as the policy's spill."""

from __future__ import annotations

import pytest

from grits_lab.cli import main
from grits_lab.errors import InputError
from grits_lab.sim import SimConfig
from grits_lab.sim.env import ScoopEnv

BOULDERS = """foods:
  boulders:
    split: train
    description: six spheres of 5 cm radius (the validator accepts them; the bowl cannot hold them)
    success_rule: items
    levels: {low: {pieces: 6}}
    components:
      - shape: sphere
        radius: [0.05, 0.05]
        mass: [0.01, 0.01]
        lateral_friction: [0.5, 0.5]
        rolling_friction: [0.001, 0.001]
        spinning_friction: [0.001, 0.001]
        restitution: [0.05, 0.05]
"""


@pytest.fixture
def boulders(tmp_path):
    path = tmp_path / "boulders.yaml"
    path.write_text(BOULDERS)
    return path


def test_a_food_that_does_not_settle_inside_the_bowl_is_refused_at_reset(boulders):
    env = ScoopEnv(SimConfig(foods_file=str(boulders)))
    with pytest.raises(InputError, match=r"'boulders' \(level 'low', seed 0\): \d of 6 particles came to rest outside the source bowl"):
        env.reset(seed=0, options={"food": "boulders", "level": "low"})


def test_the_expert_rollout_of_that_food_exits_2_in_one_line_instead_of_reporting_a_spill(boulders, capsys):
    code = main(["rollout", "--expert", "--food", "boulders", "--level", "low", "--episode-seed", "0", "--foods-file", str(boulders), "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "came to rest outside the source bowl" in lines[0]


def test_a_library_food_settles_wholly_inside_the_bowl_and_starts_with_nothing_spilled():
    env = ScoopEnv(SimConfig())
    env.reset(seed=3, options={"food": "soybeans", "level": "high"})
    assert env.initial_outside == 0 and env.metrics()["spilled"] == 0
