"""Every spilled particle attributed: the stage it was lost in and its cause, on constructed particle states."""

from __future__ import annotations

import numpy as np
import pytest

from grits_lab.sim.spill_metrics import SPILL_CAUSES, SPILL_STAGES, THROW_WINDOW, ParticleCounts, SpillTracker, attribution_columns


def _counts(in_spoon, outside, in_target=None, in_source=None):
    n = len(in_spoon)
    in_spoon, outside = np.array(in_spoon), np.array(outside)
    return ParticleCounts(in_spoon=in_spoon, in_target=np.zeros(n, bool) if in_target is None else np.array(in_target),
                          outside_source=outside, lifted=in_spoon,
                          in_source=~outside & ~in_spoon if in_source is None else np.array(in_source))


def _only(tracker, counts):
    """The non-zero entries of the tracker's attribution, as {(stage, cause): particles}."""
    cols = attribution_columns()
    return {cols[c]: n for c, n in tracker.attribution(counts).items() if n}


def test_a_particle_pushed_over_the_source_rim_during_the_scoop():
    tracker = SpillTracker(2)
    tracker.observe(_counts([False, True], [False, False]))
    after = _counts([False, True], [True, False])
    assert tracker.update(after) == 1
    assert _only(tracker, after) == {("scoop", "over_rim"): 1}


def test_a_grain_falling_off_the_moving_spoon_on_the_carry():
    tracker = SpillTracker(2)
    tracker.set_stage("carry")
    tracker.observe(_counts([True, True], [True, True], in_source=[False, False]))
    after = _counts([True, False], [True, True], in_source=[False, False])
    tracker.update(after)
    assert _only(tracker, after) == {("carry", "off_spoon"): 1}


def test_a_grain_riding_the_heap_above_the_bowl_and_landing_outside_falls_off_the_spoon_not_over_the_rim():
    tracker = SpillTracker(1)
    tracker.set_stage("lift")
    # On the heap above the rim: neither in the spoon's holding region nor in the bowl.
    tracker.observe(_counts([False], [False], in_source=[False]))
    after = _counts([False], [True], in_source=[False])
    tracker.update(after)
    assert _only(tracker, after) == {("lift", "off_spoon"): 1}


def test_a_grain_held_on_the_heaps_overhang_is_not_spilled_until_it_leaves_the_load_in_a_later_stage():
    tracker = SpillTracker(2)
    tracker.set_stage("carry")
    loaded = _counts([True, True], [True, True], in_source=[False, False])
    tracker.observe(loaded)
    # Grain 1's centre is outside the spoon's volume (the heap's overhang) but the spoon holds it.
    overhang = _counts([True, False], [True, True], in_source=[False, False])
    overhang.carried = np.array([False, True])
    assert tracker.update(overhang) == 0
    tracker.set_stage("pour")  # it leaves the load in the pour and lands beside the target
    fallen = _counts([True, False], [True, True], in_source=[False, False])
    fallen.carried = np.array([False, False])
    assert tracker.update(fallen) == 1
    assert _only(tracker, fallen) == {("pour", "poured_outside"): 1}
    assert tracker.spill_step.tolist() == [-1, 1]  # counted from the action it left the load


def test_food_poured_beside_the_target_bowl_is_poured_outside_and_food_in_it_is_delivered():
    tracker = SpillTracker(2)
    tracker.set_stage("pour")
    tracker.observe(_counts([True, True], [True, True], in_source=[False, False]))
    after = _counts([False, False], [True, True], in_target=[True, False], in_source=[False, False])
    assert tracker.update(after) == 1
    assert _only(tracker, after) == {("pour", "poured_outside"): 1}


def test_a_particle_that_bounces_out_of_the_target_bowl_counts_as_bounced_out_even_if_it_was_airborne_first():
    tracker = SpillTracker(1)
    tracker.set_stage("pour")
    tracker.observe(_counts([True], [True], in_source=[False]))
    # Falling from the spoon, above the target's counting region: counted spilled for now.
    tracker.update(_counts([False], [True], in_source=[False]))
    # Lands in the target bowl: delivered, no longer counted.
    landed = _counts([False], [True], in_target=[True], in_source=[False])
    assert tracker.update(landed) == 0 and _only(tracker, landed) == {}
    tracker.set_stage("after_pour")
    out = _counts([False], [True], in_source=[False])
    assert tracker.update(out) == 1
    assert _only(tracker, out) == {("after_pour", "bounced_out"): 1}


def test_food_thrown_when_a_joint_steps_beyond_the_pandas_limit_is_a_posture_flip_for_a_few_actions():
    tracker = SpillTracker(3)
    tracker.set_stage("carry")
    tracker.observe(_counts([True, True, True], [True] * 3, in_source=[False] * 3))
    tracker.update(_counts([True, True, True], [True] * 3, in_source=[False] * 3), thrown=True)
    # One grain lands on the next action, still within the window: thrown.
    tracker.update(_counts([False, True, True], [True] * 3, in_source=[False] * 3))
    for _ in range(THROW_WINDOW):
        tracker.update(_counts([False, True, True], [True] * 3, in_source=[False] * 3))
    # Long after the flip another falls off: the carry's own doing.
    final = _counts([False, False, True], [True] * 3, in_source=[False] * 3)
    tracker.update(final)
    assert _only(tracker, final) == {("carry", "posture_flip"): 1, ("carry", "off_spoon"): 1}


def test_counts_and_first_spill_step_are_the_spilled_particles_whatever_their_attribution():
    tracker = SpillTracker(3)
    tracker.observe(_counts([False, True, True], [False] * 3))
    tracker.update(_counts([False, True, True], [False] * 3))
    tracker.set_stage("carry")
    final = _counts([False, False, True], [True, True, True], in_source=[False] * 3)
    assert tracker.update(final) == 2
    assert tracker.first_spill_step == 1 and tracker.history == [0, 2]
    assert sum(tracker.attribution(final).values()) == tracker.current(final) == 2


def test_the_vocabulary_and_an_unknown_stage():
    assert SPILL_STAGES == ("scoop", "lift", "carry", "pour", "after_pour")
    assert set(SPILL_CAUSES) == {"over_rim", "off_spoon", "poured_outside", "bounced_out", "posture_flip"}
    assert len(attribution_columns()) == 25 and "spilled_after_pour_bounced_out" in attribution_columns()
    with pytest.raises(ValueError, match="unknown stage 'transfer'"):
        SpillTracker(1).set_stage("transfer")
