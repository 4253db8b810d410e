"""The food library: the paper's 16 foods, their splits and levels, and validation on load."""

from __future__ import annotations

import numpy as np
import pytest

from grits_lab.errors import ConfigError, InputError
from grits_lab.sim.foods import SHAPES, load_foods, primitive_food, sample_particles

TRAIN = {"brown_rice", "soybeans", "mung_beans", "chocolate_balls", "dried_jujube", "orange"}
UNSEEN = {"sago", "red_bean", "mentos", "marshmallow", "fudge", "penne", "prune", "ramen_snack", "nuts", "milk_tea"}


def test_packaged_library_has_the_papers_foods_splits_and_levels():
    lib = load_foods()
    assert set(lib.names("train")) == TRAIN
    assert set(lib.names("unseen")) == UNSEEN
    for name in TRAIN:
        assert len(lib.get(name).levels) == (1 if name == "orange" else 3), name
    for name in UNSEEN:
        assert len(lib.get(name).levels) == 2, name
    shapes = {c.shape for f in lib.foods.values() for c in f.components}
    assert shapes == set(SHAPES)
    # Counts grow with the level.
    for name, food in lib.foods.items():
        counts = list(food.levels.values())
        assert counts == sorted(counts), name


def test_recipes_reflect_the_food():
    lib = load_foods()
    milk_tea = lib.get("milk_tea").components
    assert len(milk_tea) == 2 and milk_tea[0].lateral_friction[1] < 0.1 and milk_tea[1].radius[0] > milk_tea[0].radius[1]
    assert lib.get("fudge").components[0].lateral_friction[0] >= 1.0  # sticky
    assert lib.get("marshmallow").components[0].contact_stiffness is not None  # soft
    assert len({c.shape for c in lib.get("nuts").components}) == 3  # a mixture
    assert lib.get("penne").components[0].shape == "cylinder"
    assert lib.get("sago").components[0].radius[1] <= 0.003  # small spheres


def _write(tmp_path, text):
    path = tmp_path / "foods.yaml"
    path.write_text(text)
    return path


GOOD = """
foods:
  peas:
    split: train
    levels: {low: 10}
    components:
      - shape: sphere
        radius: [0.004, 0.005]
        mass: [MASS_LO, 0.001]
"""


def test_user_food_file_loads(tmp_path):
    lib = load_foods(_write(tmp_path, GOOD.replace("MASS_LO", "0.0005")))
    assert lib.names() == ["peas"]


def test_negative_mass_is_one_clear_line_naming_food_and_key(tmp_path):
    with pytest.raises(ConfigError) as exc:
        load_foods(_write(tmp_path, GOOD.replace("MASS_LO", "-0.001")))
    message = str(exc.value)
    assert "\n" not in message and "foods.peas.components[0].mass" in message


def test_unknown_key_and_bad_shape_are_rejected(tmp_path):
    with pytest.raises(ConfigError, match="radiuss"):
        load_foods(_write(tmp_path, GOOD.replace("MASS_LO", "0.0005").replace("radius:", "radiuss:")))
    with pytest.raises(ConfigError, match="shape"):
        load_foods(_write(tmp_path, GOOD.replace("MASS_LO", "0.0005").replace("sphere", "torus")))


def test_unknown_food_and_level_are_input_errors():
    lib = load_foods()
    with pytest.raises(InputError, match="unknown food"):
        lib.get("pizza")


def test_sampling_is_seeded_and_splits_counts():
    food = load_foods().get("nuts")
    a = sample_particles(food, 50, np.random.default_rng(3))
    b = sample_particles(food, 50, np.random.default_rng(3))
    assert sum(p.count for p in a) == 50
    assert [p.radius for p in a] == [p.radius for p in b]
    assert all(np.array_equal(x.mass, y.mass) for x, y in zip(a, b))


@pytest.mark.parametrize("shape", SHAPES)
def test_primitive_food_follows_the_authors_ranges(shape):
    spec, count = primitive_food(shape, np.random.default_rng(0))
    c = spec.components[0]
    assert c.shape == shape and count % 16 == 0 and count >= 16
    assert 0.0025 <= c.radius[0] <= 0.010 and 0.0001 <= c.mass[0] <= 0.005
