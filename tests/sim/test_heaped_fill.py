"""A heaped fill (`SimConfig.heap_azimuth_deg`): the same food packed into one half of the source bowl
settles as a pile standing higher against that wall; None keeps the level fill every protocol uses."""

from __future__ import annotations

import numpy as np
import pytest

from grits_lab.errors import ConfigError
from grits_lab.sim import SimConfig
from grits_lab.sim.env import ScoopEnv
from grits_lab.sim.foods import load_foods, level_count, sample_particles
from grits_lab.sim.shapes import BowlGeometry
from grits_lab.sim.world import pack_in_bowl

CENTRE = np.array([0.6, -0.1, 0.0])


def _slots(azimuth, seed=0):
    spec = load_foods(None).get("soybeans")
    rng = np.random.default_rng(seed)
    components = sample_particles(spec, level_count(spec, "soybeans", "high"), rng)
    return pack_in_bowl(components, BowlGeometry(), CENTRE, rng, azimuth)[0] - CENTRE


@pytest.mark.parametrize("azimuth", [0.0, 90.0, 225.0])
def test_a_heaped_pack_fills_only_the_half_of_the_bowl_on_its_side(azimuth):
    side = np.array([np.cos(np.radians(azimuth)), np.sin(np.radians(azimuth))])
    heaped, level = _slots(azimuth), _slots(None)
    assert len(heaped) == len(level)
    # every slot on the heap's side of the axis, up to the millimetre of jitter a slot gets
    assert (heaped[:, :2] @ side).min() > -0.002
    # the level fill uses both halves; the heaped one stacks the same particles higher
    assert (level[:, :2] @ side).min() < -0.02
    assert heaped[:, 2].max() > level[:, 2].max() + 0.005


def test_a_heaped_fill_settles_as_a_pile_standing_higher_against_its_wall():
    tops = {}
    for azimuth in (None, 0.0):
        env = ScoopEnv(SimConfig(heap_azimuth_deg=azimuth))
        try:
            env.reset(seed=3, options={"food": "soybeans", "level": "high"})
            pos = env.world.particle_positions() - env.world.source_bowl_position
            assert env.world.settle_time_s < env.config.settle_max_s  # the pile came to rest
        finally:
            env.close()
        far, near = pos[:, 0] > 0.02, pos[:, 0] < -0.02
        tops[azimuth] = (pos[far, 2].max() if far.any() else 0.0, pos[near, 2].max() if near.any() else 0.0)
    (level_far, level_near), (heap_far, heap_near) = tops[None], tops[0.0]
    assert abs(level_far - level_near) < 0.01  # level: within a grain of each other
    assert heap_far - heap_near > 0.01  # heaped against +x: over a centimetre higher there


def test_a_heap_azimuth_out_of_range_is_refused():
    with pytest.raises(ConfigError, match="heap_azimuth_deg"):
        SimConfig(heap_azimuth_deg=720.0)
