"""Checkpoint files: tensors and plain data load; a planted pickle is refused in one line and never runs."""

from __future__ import annotations

import pytest
import torch

from grits_lab.errors import InputError, StorageError
from grits_lab.training.checkpoints import load_checkpoint, save_checkpoint


def test_a_checkpoint_of_tensors_and_plain_data_round_trips(tmp_path):
    state = {"model": {"w": torch.arange(3.0)}, "step": 4, "rng": [torch.ones(2, dtype=torch.uint8), None], "name": "x", "f": 0.5}
    loaded = load_checkpoint(save_checkpoint(tmp_path / "last.pt", state))
    assert torch.equal(loaded["model"]["w"], state["model"]["w"]) and loaded["step"] == 4 and loaded["rng"][1] is None


def test_a_planted_pickle_is_refused_naming_the_file_and_nothing_runs(tmp_path, plant_pickle):
    good = save_checkpoint(tmp_path / "good.pt", {"model": {"w": torch.zeros(2)}})
    planted = tmp_path / "last.pt"
    marker = plant_pickle(good, planted)
    with pytest.raises(InputError) as refused:
        load_checkpoint(planted)
    message = str(refused.value)
    assert not marker.exists()
    assert str(planted) in message and "\n" not in message and "system" in message


def test_a_file_that_is_not_a_checkpoint_is_reported_as_unreadable_or_refused(tmp_path):
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    with pytest.raises((InputError, StorageError), match=str(junk)):
        load_checkpoint(junk)
