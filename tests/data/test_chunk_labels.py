"""Chunk and horizon labels on constructed episodes (grits_lab/data/chunk_labels.py)."""

import numpy as np

from grits_lab.data.chunk_labels import chunk_labels, horizon_labels


def test_a_chunk_that_spills_nothing_itself_is_horizon_positive_when_its_load_sheds_in_the_carry():
    # Two scoop chunks of 3 actions that spill nothing, then a carry of 4 steps in which the heap
    # the scoop lifted sheds 2 particles at step 8.
    until_delivery = np.array([0, 0, 0, 0, 0, 0, 0, 0, 2, 2])
    starts, chunk = chunk_labels(until_delivery, 3, n_steps=6)
    np.testing.assert_array_equal(starts, [0, 3])
    np.testing.assert_array_equal(chunk, [False, False])
    np.testing.assert_array_equal(horizon_labels([8, 8], starts), [True, True])


def test_the_horizon_starts_at_the_chunks_first_action():
    # chunk 0 spills during its own actions (step 1), nothing spills after it: chunk 1 is negative by both labels
    until_delivery = np.array([0, 1, 1, 1, 1, 1, 1, 1])
    starts, chunk = chunk_labels(until_delivery, 3, n_steps=6)
    np.testing.assert_array_equal(chunk, [True, False])
    np.testing.assert_array_equal(horizon_labels([1], starts), [True, False])
    np.testing.assert_array_equal(horizon_labels([3], starts), [True, True])  # a spill at a chunk's first step is its own


def test_food_in_flight_to_the_target_is_no_spill_but_food_that_ends_outside_is():
    # Every pour: the spilled count rises while food flies from the spoon to the target and falls
    # when it lands. Nothing ends outside: no chunk is blamed.
    np.testing.assert_array_equal(horizon_labels(np.array([], dtype=np.int32), [0, 3, 6]), [False, False, False])
    # one particle ends on the table, having left at step 7 (say, bounced out of the target)
    np.testing.assert_array_equal(horizon_labels([7], [0, 3, 6]), [True, True, True])
    np.testing.assert_array_equal(horizon_labels([4], [0, 3, 6]), [True, True, False])


def test_a_negative_chunk_start_is_refused():
    import pytest

    with pytest.raises(ValueError, match="non-negative"):
        horizon_labels([1], [-1, 0])
