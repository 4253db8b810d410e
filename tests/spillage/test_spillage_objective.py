"""The guidance objective: slices the executed chunk, maps normalizer spaces, gives usable gradients."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from grits_lab.config import config_from_dict
from grits_lab.data.normalize import ActionNormalizer
from grits_lab.errors import InputError
from grits_lab.spillage.predictor_checkpoint import TrainedPredictor
from grits_lab.spillage.predictor_config import PredictorConfig
from grits_lab.spillage.guidance_objective import SpillageObjective
from grits_lab.spillage.model import CloudNormalizer, SpillagePredictor


@pytest.fixture
def predictor():
    torch.manual_seed(0)
    cfg = config_from_dict(PredictorConfig, {"model": {"dp3": {"hidden_dims": [16, 32], "out_dim": 16}}})
    model = SpillagePredictor(cfg.model).eval().requires_grad_(False)
    rng = np.random.default_rng(0)
    poses = np.concatenate([rng.uniform([0.4, -0.1, 0.0], [0.6, 0.1, 0.2], (100, 3)), rng.uniform(-1, 1, (100, 6))], 1)
    return TrainedPredictor(model, ActionNormalizer().fit(poses), CloudNormalizer(centre=(0.5, 0, 0.05)), cfg), poses


def test_objective_judges_only_the_executed_chunk(predictor):
    pred, _ = predictor
    cloud = np.random.default_rng(1).normal([0.5, 0, 0.05], 0.05, (3, 40, 3))
    objective = SpillageObjective(pred, cloud, n_obs_steps=5, n_action_steps=12)
    traj = torch.zeros(2, 16, 9).uniform_(-1, 1).requires_grad_(True)
    cost = objective(traj)
    assert cost.shape == (2,)
    (grad,) = torch.autograd.grad(cost.sum(), traj)
    assert torch.isfinite(grad).all()
    assert grad[:, :4].abs().sum() == 0  # past steps are not judged
    assert grad[:, 4:16].abs().sum() > 0
    direct = pred.spill_probability(traj[:, 4:16], pred.encode_cloud(cloud))
    torch.testing.assert_close(cost, direct)  # identity map without a policy normalizer


def test_policy_normalizer_space_is_mapped_into_the_predictors(predictor):
    pred, poses = predictor
    policy_norm = ActionNormalizer().fit(poses * np.array([1.3] * 3 + [1] * 6) + np.array([0.02] * 3 + [0] * 6))
    cloud = np.random.default_rng(2).normal([0.5, 0, 0.05], 0.05, (3, 40, 3))
    world = np.concatenate([np.random.default_rng(3).uniform([0.45, -0.05, 0.05], [0.55, 0.05, 0.15], (1, 16, 3)), np.tile([1, 0, 0, 0, 1, 0], (1, 16, 1))], -1)
    via_policy = SpillageObjective(pred, cloud, policy_normalizer=policy_norm)(torch.tensor(policy_norm.normalize(world), dtype=torch.float32))
    expected = pred.predict_world(world[:, 4:16], cloud[None])
    np.testing.assert_allclose(via_policy.numpy(), expected, atol=1e-5)
    same = SpillageObjective(pred, cloud, policy_normalizer=pred.action_normalizer)
    torch.testing.assert_close(same.scale, torch.ones(9)) ; torch.testing.assert_close(same.offset, torch.zeros(9), atol=1e-6, rtol=0)


def test_bad_horizon_and_chunk_length_are_refused(predictor):
    pred, _ = predictor
    cloud = np.zeros((3, 8, 3))
    with pytest.raises(InputError, match="executes 8"):
        SpillageObjective(pred, cloud, n_action_steps=8)
    with pytest.raises(InputError, match="shorter"):
        SpillageObjective(pred, cloud)(torch.zeros(1, 10, 9))
