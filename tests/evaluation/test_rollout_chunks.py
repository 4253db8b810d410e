"""Rollout chunks (evaluate with rollout_chunks: true) carry horizon labels through the transfer and pour."""

import numpy as np

from grits_lab.evaluation.task_episode import rollout_chunk_episode


def test_rollout_chunks_are_horizon_labelled_through_the_whole_task():
    actions = np.zeros((24, 9), dtype=np.float32)
    cloud = np.zeros((3, 4, 3), dtype=np.float32)
    scoop = [0] * 24 + [0] * 5  # the scoop and its settling spill nothing
    task = scoop + [0] * 30 + [3, 2] + [2] * 8  # three particles leave in the carry; one lands back in a bowl
    chunks = {"log": [(0, cloud, 0), (12, cloud, 0)], "actions": list(actions), "spilled_over_time": scoop}
    episode = rollout_chunk_episode({**chunks, "spilled_until_delivery": task, "spill_steps": [59, 59]}, 12, {"food": "rice"})
    arrays, meta = episode["arrays"], episode["meta"]
    np.testing.assert_array_equal(arrays["chunk_spilled"], [False, False])
    np.testing.assert_array_equal(arrays["chunk_spilled_horizon"], [True, True])
    assert (meta["label"], meta["label_horizon"], meta["n_chunks_spilled_horizon"]) == (0, 1, 2)
    assert len(arrays["spilled_until_delivery"]) == len(task)
    # a pour whose food was in flight (the count rose and fell) and all landed in the target: no spill
    delivered = rollout_chunk_episode({**chunks, "spilled_until_delivery": scoop + [0] * 30 + [4, 0] + [0] * 8,
                                       "spill_steps": []}, 12, {"food": "rice"})
    np.testing.assert_array_equal(delivered["arrays"]["chunk_spilled_horizon"], [False, False])
