"""The predictor network: shapes, trajectory gradient, baselines, batch broadcasting."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from grits_lab.spillage.predictor_config import PointNet2EncoderConfig, PredictorModelConfig, SetAbstractionConfig
from grits_lab.spillage.model import CloudNormalizer, SpillagePredictor

SMALL_PN2 = PointNet2EncoderConfig(levels=[SetAbstractionConfig(16, 1.0, 8, (16,))], global_mlp=(32,), out_dim=16)


def _inputs(b=4, n=32, seed=0):
    rng = np.random.default_rng(seed)
    traj = torch.from_numpy(rng.uniform(-1, 1, (b, 12, 9)).astype(np.float32))
    cloud = torch.from_numpy(rng.normal(size=(b, 3, n, 3)).astype(np.float32))
    return traj, cloud


@pytest.mark.parametrize("encoder", ["dp3", "pointnet2"])
def test_gradient_with_respect_to_the_trajectory_is_finite_and_nonzero(encoder):
    torch.manual_seed(0)
    model = SpillagePredictor(PredictorModelConfig(encoder=encoder, pointnet2=SMALL_PN2)).eval()
    traj, cloud = _inputs()
    traj.requires_grad_(True)
    emb = model.encode_cloud(cloud)
    p = model.spill_probability(traj, emb)
    assert p.shape == (4,) and ((p > 0) & (p < 1)).all()
    (grad,) = torch.autograd.grad(p.sum(), traj)
    assert torch.isfinite(grad).all()
    assert (grad.abs().sum(dim=(1, 2)) > 0).all()  # every sample gets a direction


def test_baselines_use_only_their_input():
    torch.manual_seed(0)
    traj, cloud = _inputs()
    traj_only = SpillagePredictor(PredictorModelConfig(inputs="trajectory")).eval()
    assert traj_only.encode_cloud(cloud).shape == (4, 0)
    torch.testing.assert_close(traj_only(traj, cloud), traj_only(traj, cloud * 3))
    cloud_only = SpillagePredictor(PredictorModelConfig(inputs="cloud")).eval()
    torch.testing.assert_close(cloud_only(traj, cloud), cloud_only(-traj, cloud))
    full = SpillagePredictor(PredictorModelConfig()).eval()
    assert (full(traj, cloud) - full(-traj, cloud)).abs().max() > 1e-4
    assert (full(traj, cloud) - full(traj, cloud * 3)).abs().max() > 1e-4


def test_one_cloud_embedding_broadcasts_over_a_trajectory_batch():
    torch.manual_seed(0)
    model = SpillagePredictor(PredictorModelConfig()).eval()
    traj, cloud = _inputs()
    emb = model.encode_cloud(cloud[:1])
    torch.testing.assert_close(model.logits(traj, emb), model.logits(traj, emb.expand(4, -1)))


def test_wrong_trajectory_shape_is_refused():
    model = SpillagePredictor(PredictorModelConfig())
    with pytest.raises(ValueError, match=r"\(B, 12, 9\)"):
        model.logits(torch.zeros(2, 16, 9), torch.zeros(2, model.cloud_dim))


def test_cloud_normalizer_centres_on_the_bowl():
    cloud = np.zeros((2, 3, 10, 3))
    cloud[:, 2] = [0.5, 0.1, 0.05]
    norm = CloudNormalizer(scale=0.1).fit(cloud)
    np.testing.assert_allclose(norm.centre, [0.5, 0.1, 0.05])
    np.testing.assert_allclose(norm.normalize(cloud)[:, 2], 0.0, atol=1e-6)
    t = norm.normalize(torch.from_numpy(cloud).float())
    np.testing.assert_allclose(t.numpy(), norm.normalize(cloud), atol=1e-6)
    assert CloudNormalizer().load_state_dict(norm.state_dict()).centre.tolist() == norm.centre.tolist()
