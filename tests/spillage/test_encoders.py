"""Point encoders: order invariance, object identity, farthest-point sampling and ball query."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from grits_lab.spillage.predictor_config import DP3EncoderConfig, PointNet2EncoderConfig, SetAbstractionConfig
from grits_lab.spillage.cloud_encoders import DP3Encoder, PointNet2Encoder, ball_query, farthest_point_indices


def _cloud(b=2, n=64, seed=0):
    return torch.from_numpy(np.random.default_rng(seed).normal(size=(b, 3, n, 3)).astype(np.float32))


@pytest.mark.parametrize("per_object", [True, False])
def test_dp3_is_invariant_to_point_order_within_each_object(per_object):
    torch.manual_seed(0)
    enc = DP3Encoder(DP3EncoderConfig(pool_per_object=per_object)).eval()
    cloud = _cloud()
    perm = torch.stack([torch.randperm(cloud.shape[2]) for _ in range(3)])
    shuffled = torch.stack([cloud[:, k, perm[k]] for k in range(3)], dim=1)
    torch.testing.assert_close(enc(cloud), enc(shuffled), rtol=1e-5, atol=1e-5)


def test_dp3_tells_objects_apart():
    """Swapping which points are food and which are bowl must change the embedding."""
    torch.manual_seed(0)
    enc = DP3Encoder(DP3EncoderConfig()).eval()
    cloud = _cloud()
    swapped = cloud[:, [2, 1, 0]]
    assert (enc(cloud) - enc(swapped)).abs().max() > 1e-3


def _fps_reference(xyz, m):
    chosen = [0]
    d = np.full(len(xyz), np.inf)
    for _ in range(m - 1):
        d = np.minimum(d, ((xyz - xyz[chosen[-1]]) ** 2).sum(1))
        chosen.append(int(d.argmax()))
    return chosen


def test_farthest_point_indices_on_a_line_and_against_a_reference():
    line = torch.tensor([[[float(i), 0.0, 0.0] for i in range(11)]])
    # from 0: the far end, then the middle, then the quarter points
    assert farthest_point_indices(line, 4)[0].tolist() == [0, 10, 5, 2]
    xyz = np.random.default_rng(3).normal(size=(2, 200, 3)).astype(np.float32)
    got = farthest_point_indices(torch.from_numpy(xyz), 20).numpy()
    for b in range(2):
        assert got[b].tolist() == _fps_reference(xyz[b].astype(np.float64), 20)
        assert len(set(got[b].tolist())) == 20


def test_ball_query_takes_first_points_in_index_order_and_pads():
    xyz = torch.tensor([[[0.0, 0, 0], [5.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0], [9.0, 0, 0]]])
    centres = torch.tensor([[[0.0, 0, 0], [5.0, 0, 0]]])
    idx = ball_query(xyz, centres, radius=0.25, n_neighbors=3)
    assert idx[0, 0].tolist() == [0, 2, 3]  # 4 (0.3) is outside, and only 3 are kept
    assert idx[0, 1].tolist() == [1, 1, 1]  # lone point: padded with itself
    idx = ball_query(xyz, centres, radius=0.35, n_neighbors=8)
    assert idx[0, 0].tolist() == [0, 2, 3, 4, 0, 0, 0, 0]


def test_pointnet2_runs_is_differentiable_and_roughly_order_robust():
    torch.manual_seed(0)
    cfg = PointNet2EncoderConfig(levels=[SetAbstractionConfig(32, 0.8, 8, (16, 32)), SetAbstractionConfig(8, 1.6, 8, (32,))], global_mlp=(32,), out_dim=16, norm="layer")
    enc = PointNet2Encoder(cfg)
    cloud = _cloud(n=40).requires_grad_(True)
    out = enc(cloud)
    assert out.shape == (2, 16)
    out.sum().backward()
    assert torch.isfinite(cloud.grad).all() and cloud.grad.abs().sum() > 0
