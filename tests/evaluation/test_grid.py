"""The episode grid: which (food, level, trial) episodes a run plays and their seeds."""

import pytest

from grits_lab.errors import ConfigError
from grits_lab.evaluation import EpisodeGrid
from grits_lab.sim.foods import load_foods


def test_a_protocol_split_at_first_trial_plays_the_same_episodes_as_the_whole_run():
    library = load_foods()
    whole = EpisodeGrid(foods=["sago", "prune"], levels=[], trials=10, seed=0).keys(library)
    first = EpisodeGrid(foods=["sago", "prune"], levels=[], trials=5, seed=0).keys(library)
    second = EpisodeGrid(foods=["sago", "prune"], levels=[], trials=5, first_trial=5, seed=0).keys(library)
    assert sorted(first + second, key=lambda k: (k.food, k.level, k.trial)) == sorted(whole, key=lambda k: (k.food, k.level, k.trial))
    assert {k.trial for k in second} == {5, 6, 7, 8, 9}
    assert not {k.seed for k in first} & {k.seed for k in second}


def test_a_negative_first_trial_is_refused_naming_the_key():
    with pytest.raises(ConfigError, match="`first_trial` must be non-negative"):
        EpisodeGrid(first_trial=-1)
