"""Data-parallel training on CPU processes: the gradient of the whole batch, exact resume, errors."""

import numpy as np
import pandas as pd
import pytest
import torch

from grits_lab.config import config_from_dict
from grits_lab.errors import ConfigError, StorageError
from grits_lab.policies.diffusion.training_diffusion import PolicyTrainConfig, train_policy
from grits_lab.training.data_parallel import batch_share, reduce_gradients, run_processes

from .test_diffusion_policy import _train_config


def _regression_batch():
    gen = torch.Generator().manual_seed(3)
    return torch.randn(11, 4, generator=gen), torch.randn(11, 2, generator=gen)


def _gradient(rank, world_size):
    """The gradient process `rank` holds after the all-reduce, on an uneven 11-sample batch."""
    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(4, 8), torch.nn.Tanh(), torch.nn.Linear(8, 2))
    x, y = _regression_batch()
    part, share = batch_share(np.arange(11), rank, world_size)
    loss = torch.nn.functional.mse_loss(model(x[part]), y[part])
    (loss * share).backward()
    batch_loss = reduce_gradients(model, loss * share)
    return batch_loss, [p.grad.clone() for p in model.parameters()]


def _fail_in_second_process(rank, world_size):
    if rank == 1:
        raise StorageError(f"process {rank} of {world_size} cannot read its shard")
    torch.distributed.barrier()  # process 0 waits on process 1 until it is stopped


def test_batch_share_splits_every_index_once_with_weights_summing_to_one():
    shares = [batch_share(np.arange(11), r, 3) for r in range(3)]
    assert np.array_equal(np.concatenate([s[0] for s in shares]), np.arange(11))
    assert sum(s[1] for s in shares) == pytest.approx(1.0)
    assert [len(s[0]) for s in shares] == [4, 4, 3]


def test_two_processes_apply_the_gradient_of_the_whole_batch(tmp_path, monkeypatch):
    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(4, 8), torch.nn.Tanh(), torch.nn.Linear(8, 2))
    x, y = _regression_batch()
    loss = torch.nn.functional.mse_loss(model(x), y)
    loss.backward()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "results" / "run").mkdir(parents=True)
    batch_loss, grads = run_processes(_gradient, 2, (), "results/run")  # a relative directory, as configs give them
    assert batch_loss == pytest.approx(float(loss.detach()), rel=1e-5)
    for p, g in zip(model.parameters(), grads):
        torch.testing.assert_close(g, p.grad, rtol=1e-5, atol=1e-6)


def test_two_process_training_resumes_to_the_weights_of_an_uninterrupted_run(demo_dataset, tmp_path):
    straight = train_policy(_train_config(demo_dataset, tmp_path / "a", num_processes=2), progress=False)
    assert straight["num_processes"] == 2 and straight["steps"] == 20
    train_policy(_train_config(demo_dataset, tmp_path / "b", num_processes=2), max_steps=10, progress=False)
    resumed = train_policy(_train_config(demo_dataset, tmp_path / "b", num_processes=2), progress=False)
    assert resumed["resumed_from"] == 10 and resumed["steps"] == 20
    sa = torch.load(straight["checkpoint"], weights_only=True)
    sb = torch.load(resumed["checkpoint"], weights_only=True)
    assert len(sb["torch_rng_processes"]) == 2
    for key, value in sa["policy"]["model"].items():
        torch.testing.assert_close(sb["policy"]["model"][key], value, rtol=1e-5, atol=1e-6)
    log = pd.read_csv(tmp_path / "b" / "metrics.csv")
    assert list(log["step"]) == [5, 10, 15, 20] and log["train_loss"].notna().all()
    # a run with one process differs only in its noise draws: it starts from the same loss scale
    single = train_policy(_train_config(demo_dataset, tmp_path / "c"), progress=False)
    assert single["num_processes"] == 1
    assert abs(single["first_loss"] - straight["first_loss"]) < 0.5 * single["first_loss"]


def test_data_parallel_refusals_name_the_key(demo_dataset, tmp_path):
    with pytest.raises(ConfigError, match="num_processes"):
        _train_config(demo_dataset, tmp_path / "x", num_processes=0)
    with pytest.raises(ConfigError, match="num_processes"):
        _train_config(demo_dataset, tmp_path / "x", num_processes=17, batch_size=16)
    with pytest.raises(ConfigError, match="rollout.every"):
        _train_config(demo_dataset, tmp_path / "x", num_processes=2, rollout={"every": 5})
    with pytest.raises(StorageError, match="not found"):
        train_policy(_train_config(tmp_path / "missing", tmp_path / "out", num_processes=2), progress=False)
    assert not (tmp_path / "out").exists()  # refused before any process started


def test_an_error_inside_a_process_reaches_the_caller_with_its_type(tmp_path):
    with pytest.raises(StorageError, match="process 1 of 2 cannot read its shard"):
        run_processes(_fail_in_second_process, 2, (), tmp_path)
    assert list(tmp_path.iterdir()) == []  # no rendezvous or result file left behind


def test_config_keeps_one_process_by_default(demo_dataset, tmp_path):
    assert config_from_dict(PolicyTrainConfig, {"dataset": "d", "output_dir": "o"}).num_processes == 1


def test_a_checkpoint_from_before_data_parallel_training_resumes_exactly(demo_dataset, tmp_path):
    straight = train_policy(_train_config(demo_dataset, tmp_path / "a"), progress=False)
    train_policy(_train_config(demo_dataset, tmp_path / "b"), max_steps=10, progress=False)
    last = tmp_path / "b" / "checkpoints" / "last.pt"
    old = torch.load(last, weights_only=True)
    old["torch_rng"] = old.pop("torch_rng_processes")[0]  # the single generator state older checkpoints kept
    torch.save(old, last)
    resumed = train_policy(_train_config(demo_dataset, tmp_path / "b"), progress=False)
    sa = torch.load(straight["checkpoint"], weights_only=True)
    sb = torch.load(resumed["checkpoint"], weights_only=True)
    for key, value in sa["policy"]["model"].items():
        torch.testing.assert_close(sb["policy"]["model"][key], value, rtol=1e-5, atol=1e-6)
