"""The food library: the paper's 16 foods, their splits and levels, and validation on load."""

from __future__ import annotations

import numpy as np
import pytest

from grits_lab.errors import ConfigError, InputError
from dataclasses import replace

from grits_lab.sim.foods import SHAPES, bowl_volume, fill_count, level_count, load_foods, primitive_food, sample_particles
from grits_lab.sim.shapes import BowlGeometry

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
    levels: {low: {pieces: 10}}
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
    assert c.shape == shape and count >= 1
    assert 0.0045 <= c.radius[0] <= 0.010 and 0.0001 <= c.mass[0] <= 0.005
    height = spec.levels["trial"].fill_height
    assert 0.012 <= height <= 0.032
    assert count == fill_count(spec, height)


def test_fill_count_follows_the_bowl_volume_and_the_grain_size():
    food = load_foods().get("mung_beans")
    # Twice the height holds more than twice the volume in a bowl that widens upwards.
    assert fill_count(food, 0.02) > 2 * fill_count(food, 0.01)
    # Coarse-graining by k divides the count by k^3 for the same volume.
    coarse = replace(food, components=[replace(food.components[0], coarse_grain=2 * food.components[0].coarse_grain)])
    assert abs(fill_count(coarse, 0.028) - fill_count(food, 0.028) / 8) <= 1
    # A cylinder of height h and radius r of volume V: spheres of radius a fill it with about 0.6 V / (4/3 pi a^3).
    bowl = BowlGeometry(floor_radius=0.05, rim_radius=0.05)
    assert bowl_volume(bowl, 0.02) == pytest.approx(np.pi * 0.05**2 * 0.02)


def test_levels_are_physical_amounts_that_grow():
    lib = load_foods()
    for name, food in lib.foods.items():
        counts = [level_count(food, name, lv) for lv in food.levels]
        assert counts == sorted(counts), name
        small = food.success_rule == "coverage"
        for amount in food.levels.values():
            assert (amount.fill_height is not None) == small and (amount.pieces is not None) == (not small), name


def test_a_level_must_be_exactly_one_amount(tmp_path):
    with pytest.raises(ConfigError, match="exactly one of fill_height"):
        load_foods(_write(tmp_path, GOOD.replace("MASS_LO", "0.0005").replace("{pieces: 10}", "{pieces: 10, fill_height: 0.01}")))
    with pytest.raises(ConfigError, match="coarse_grain"):
        load_foods(_write(tmp_path, GOOD.replace("MASS_LO", "0.0005").replace("        mass:", "        coarse_grain: 0.5\n        mass:")))


def test_the_spillage_dataset_draws_its_foods_from_the_one_particle_range_definition():
    from grits_lab.config import config_from_dict
    from grits_lab.collection.spillage_trials import SpillageConfig
    from grits_lab.errors import ConfigError
    from grits_lab.sim.foods import ParticleRanges

    config = SpillageConfig()
    assert type(config.particles) is ParticleRanges and config.particles == ParticleRanges()
    assert config.shapes == list(SHAPES)
    a, _ = primitive_food("cone", np.random.default_rng(4))
    b, _ = primitive_food("cone", np.random.default_rng(4), config.particles)
    assert a == b
    with pytest.raises(ConfigError, match=r"`particles.radius` must be a range starting at >= 0.0015 m"):
        config_from_dict(SpillageConfig, {"particles": {"radius": [0.001, 0.01]}})
