"""Chunk and horizon labels on constructed spilled-count series (grits_lab/data/chunk_labels.py)."""

import numpy as np

from grits_lab.data.chunk_labels import chunk_labels, horizon_labels


def test_a_chunk_that_spills_nothing_itself_is_horizon_positive_when_its_load_sheds_in_the_carry():
    # Two scoop chunks of 3 actions that spill nothing, then a carry of 4 steps in which the heap
    # the scoop lifted sheds 2 particles.
    until_delivery = np.array([0, 0, 0, 0, 0, 0, 0, 0, 2, 2])
    starts, chunk = chunk_labels(until_delivery, 3, n_steps=6)
    np.testing.assert_array_equal(starts, [0, 3])
    np.testing.assert_array_equal(chunk, [False, False])
    np.testing.assert_array_equal(horizon_labels(until_delivery, starts), [True, True])


def test_the_horizon_starts_at_the_chunks_first_action():
    # chunk 0 spills during its own actions, nothing spills after it: chunk 1 is negative by both labels
    until_delivery = np.array([0, 1, 1, 1, 1, 1, 1, 1])
    starts, chunk = chunk_labels(until_delivery, 3, n_steps=6)
    np.testing.assert_array_equal(chunk, [True, False])
    np.testing.assert_array_equal(horizon_labels(until_delivery, starts), [True, False])
    # a particle that was already out before the first action is no spill of any chunk
    np.testing.assert_array_equal(horizon_labels(np.array([1, 1, 1, 1]), [0, 2], spilled_before=1), [False, False])


def test_food_delivered_to_the_target_is_no_spill_but_a_later_rise_is():
    # A spilled particle that lands in the target leaves the count (3 -> 2): not a spill; the rise to 3 at the end is.
    counts = np.array([0, 3, 3, 2, 2, 3])
    np.testing.assert_array_equal(horizon_labels(counts, [0, 2, 4]), [True, True, True])
    np.testing.assert_array_equal(horizon_labels(np.array([0, 3, 3, 2, 2, 2]), [0, 2, 4]), [True, False, False])


def test_without_a_carry_the_horizon_of_a_tiled_trajectory_is_any_later_chunk_label():
    counts = np.array([0, 0, 0, 0, 1, 1, 1, 1, 1, 2, 2])
    starts, chunk = chunk_labels(counts, 3)
    later = np.logical_or.accumulate(chunk[::-1])[::-1]
    np.testing.assert_array_equal(horizon_labels(counts, starts), later)
