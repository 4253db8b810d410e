"""Where spilled particles left from: over the rim, off the spoon outside the bowl, or elsewhere."""

from __future__ import annotations

import numpy as np

from grits_lab.sim.spill_metrics import SPILL_MECHANISMS, ParticleCounts, SpillTracker


def _counts(in_spoon, outside, in_target=None, in_source=None):
    n = len(in_spoon)
    in_spoon, outside = np.array(in_spoon), np.array(outside)
    return ParticleCounts(in_spoon=in_spoon, in_target=np.zeros(n, bool) if in_target is None else np.array(in_target),
                          outside_source=outside, lifted=in_spoon,
                          in_source=~outside & ~in_spoon if in_source is None else np.array(in_source))


def test_each_spilled_particle_gets_the_mechanism_of_its_last_place():
    tracker = SpillTracker(4)
    # Particle 0 sits in the bowl, 1 and 2 in the spoon over the bowl, 3 in the spoon.
    tracker.observe(_counts([False, True, True, True], [False] * 4), spoon_outside_source=False)
    # 0 is pushed over the rim; 1 falls off the spoon while it is over the bowl and bounces out.
    assert tracker.update(_counts([False, False, True, True], [True, True, False, False]), spoon_outside_source=True) == 2
    # Now the spoon is outside the bowl: 2 falls off onto the table.
    assert tracker.update(_counts([False, False, False, True], [True, True, True, True]), spoon_outside_source=True) == 3
    assert tracker.mechanisms(_counts([False, False, False, True], [True] * 4)) == {"over_rim": 1, "off_spoon": 1, "elsewhere": 1}
    assert set(SPILL_MECHANISMS) == {"over_rim", "off_spoon", "elsewhere"}


def test_a_grain_riding_the_heap_outside_the_spoon_region_falls_off_the_spoon_not_over_the_rim():
    tracker = SpillTracker(1)
    # Above the bowl, on the heap but beyond the spoon's holding region: neither in spoon nor in the bowl.
    tracker.observe(_counts([False], [False], in_source=[False]), spoon_outside_source=True)
    tracker.update(_counts([False], [True], in_source=[False]), spoon_outside_source=True)
    assert tracker.mechanisms(_counts([False], [True], in_source=[False]))["off_spoon"] == 1


def test_a_particle_poured_into_the_target_bowl_is_not_counted():
    tracker = SpillTracker(2)
    tracker.observe(_counts([True, True], [False, False]), spoon_outside_source=True)
    tracker.update(_counts([False, False], [True, True], in_target=[True, False]), spoon_outside_source=True)
    final = _counts([False, False], [True, True], in_target=[True, False])
    assert tracker.current(final) == 1 and tracker.mechanisms(final) == {"over_rim": 0, "off_spoon": 1, "elsewhere": 0}
